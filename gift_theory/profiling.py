"""Profiling hooks for the packages on top of gift (paper_figures' profiles): phase clocks with
JAX's compile time per phase and the host's matmul rate. Public re-exports of the core's own
tools."""

from ._bench import matmul_gflops as matmul_gflops
from ._phases import PhaseClock as PhaseClock
from ._phases import compile_totals as compile_totals
from ._phases import compiled_functions as compiled_functions
from ._phases import listen as listen
from ._phases import phase as phase

"""A pytest plugin: per xdist worker, JAX's trace, lowering and backend seconds per function name,
written to /tmp/compiles_WORKER.txt at the end of the run.

    PYTHONPATH=this_folder python -m pytest -n 2 -p compile_log
"""
import os, atexit
from collections import defaultdict
acc = defaultdict(lambda: [0.0, 0.0, 0.0, 0])
def _d(event, secs, **kw):
    fn = str(kw.get("fun_name", "?")).removeprefix("jit(").removesuffix(")")
    if event.endswith("jaxpr_trace_duration"): acc[fn][0] += secs; acc[fn][3] += 1
    elif event.endswith("jaxpr_to_mlir_module_duration"): acc[fn][1] += secs
    elif event.endswith("backend_compile_duration"): acc[fn][2] += secs
def pytest_configure(config):
    from jax import monitoring
    monitoring.register_event_duration_secs_listener(_d)
def pytest_unconfigure(config):
    w = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(f"/tmp/compiles_{w}.txt", "w") as fh:
        for k, v in acc.items():
            fh.write(f"{k}\t{v[0]:.4f}\t{v[1]:.4f}\t{v[2]:.4f}\t{v[3]}\n")

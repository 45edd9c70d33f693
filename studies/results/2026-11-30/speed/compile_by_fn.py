"""Trace, lowering and backend seconds (and traces) per JAX function name in one gift command.

    python compile_by_fn.py diagnose FILE.npz --seed 4 --quiet --json
"""
import sys, time
from collections import defaultdict
from jax import monitoring
acc = defaultdict(lambda: [0.0, 0.0, 0.0, 0])
def _d(event, secs, **kw):
    fn = str(kw.get("fun_name", "?"))
    if event.endswith("jaxpr_trace_duration"): acc[fn][0] += secs; acc[fn][3] += 1
    elif event.endswith("jaxpr_to_mlir_module_duration"): acc[fn][1] += secs
    elif event.endswith("backend_compile_duration"): acc[fn][2] += secs
monitoring.register_event_duration_secs_listener(_d)
from gift_theory.cli._main import main
main(sys.argv[1:])
tot = [sum(v[i] for v in acc.values()) for i in range(4)]
print(f"TOTAL trace {tot[0]:.2f} lower {tot[1]:.2f} backend {tot[2]:.2f} n {tot[3]}", file=sys.stderr)
for k, v in sorted(acc.items(), key=lambda kv: -(kv[1][0]+kv[1][1]+kv[1][2]))[:25]:
    print(f"{k[:50]:50s} trace {v[0]:.3f} lower {v[1]:.3f} backend {v[2]:.3f} n {v[3]}", file=sys.stderr)

import os, time, collections, atexit, json
import jax.monitoring as mon
TOT = collections.defaultdict(float); CNT = collections.Counter()
FN = collections.defaultdict(float); FNC = collections.Counter(); FNL = collections.Counter()
def _l(event, dur, fun_name=None, **kw):
    TOT[event] += dur; CNT[event] += 1
    if fun_name and event.startswith("/jax/core/compile"):
        k = fun_name.replace("jit(", "").rstrip(")")
        FN[k] += dur
        if "backend" in event: FNC[k] += 1
        if "mlir" in event: FNL[k] += 1
mon.register_event_duration_secs_listener(_l)
T0 = time.process_time()
def _dump():
    out = os.environ.get("JAXPROF_OUT", "/tmp/prof/out") + f".{os.getpid()}.json"
    json.dump({"cpu": time.process_time() - T0, "tot": TOT, "cnt": CNT, "fn": FN, "fnc": FNC, "fnl": FNL}, open(out, "w"), indent=1)
atexit.register(_dump)

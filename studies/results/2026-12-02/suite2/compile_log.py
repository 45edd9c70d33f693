# sitecustomize: print every XLA backend compile over 0.5 s with the gift/proofs_checks frames that asked for it
import jax.monitoring as mon, sys, traceback
def _l(event, dur, fun_name=None, **kw):
    if dur > 0.5 and "backend" in event:
        st = [f"{f.filename.split('/')[-1]}:{f.lineno}:{f.name}" for f in traceback.extract_stack()[-40:] if 'proofs_checks' in f.filename or 'gift_theory' in f.filename]
        print(f"COMPILE {dur:.2f}s {fun_name} {st[-4:]}", file=sys.stderr)
mon.register_event_duration_secs_listener(_l)

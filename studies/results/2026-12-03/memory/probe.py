"""python probe.py FILE: the arrays over 1 MB a Session holds, and the RSS after loading and after the session."""
import gc, os, sys
import jax, numpy as np
from gift_theory.lab._io import load_measurement
from gift_theory.lab._session import Session
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "2026-11-30", "memory"))  # _rss
from _rss import rss
meas = load_measurement(sys.argv[1]); print("loaded", rss())
s = Session.create(jax.random.PRNGKey(4), meas, None, 1); print("session", rss())
seen=set()
def walk(o, path, depth=0):
    if id(o) in seen or depth>8: return
    seen.add(id(o))
    if isinstance(o,(np.ndarray, jax.Array)):
        if o.nbytes>1e6: print(f"{o.nbytes/1e6:8.1f} MB {o.dtype} {o.shape} {path}")
        return
    if isinstance(o,dict):
        for k,v in o.items(): walk(v, f"{path}[{k!r}]", depth+1)
    elif isinstance(o,(list,tuple)):
        for i,v in enumerate(o): walk(v, f"{path}[{i}]", depth+1)
    elif hasattr(o,'__dict__') or hasattr(o,'__slots__'):
        d = dict(vars(o)) if hasattr(o,'__dict__') else {}
        for k in getattr(type(o),'__slots__',()) or ():
            if hasattr(o,k): d[k]=getattr(o,k)
        for k,v in d.items(): walk(v, f"{path}.{k}", depth+1)
walk(s, "s")

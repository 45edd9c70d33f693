import time, sys, jax, jax.numpy as jnp, numpy as np
from functools import partial
from gift_theory import Architecture
from gift_theory.effects import Physics
from gift_theory.chips._simulated import _measure
from gift_theory._params import Layer
from gift_theory._model import forward, site_laws, name_tag, tagged_draws
_site = jax.jit(tagged_draws, static_argnames=("shape", "law", "dtype"))
@partial(jax.jit, static_argnames=("arch", "shots", "taps", "with_t"))
def _fwd(noise, params, x, physics, *, arch, shots, taps, with_t):
    dtype = params[0].W.dtype
    n = x.shape[0] * shots
    t = (jnp.arange(n, dtype=dtype) / max(n - 1, 1)).reshape(x.shape[0], shots) if with_t else None
    out = forward(params, x[:, None, :].astype(dtype), noise, physics, arch, t=t, taps=taps)
    return out.y, (out.taps[:-1] if taps else ()), t
def split(key, params, x, physics, *, arch, shots, taps, with_t):
    dtype = params[0].W.dtype
    noise = {name: _site(key, np.uint32(name_tag(name)), (x.shape[0], shots) + tuple(ev), law, dtype)
             for name, (ev, law) in site_laws(arch, physics).items()}
    return _fwd(noise, params, x, physics, arch=arch, shots=shots, taps=taps, with_t=with_t)
arch = Architecture((16,32,16,8))
rng=np.random.default_rng(0)
params = tuple(Layer(jnp.asarray(rng.normal(size=(o,i)),jnp.float32), jnp.asarray(rng.normal(size=o),jnp.float32)) for i,o in zip(arch.widths[:-1],arch.widths[1:]))
x = jnp.asarray(rng.uniform(size=(60,16)),jnp.float32)
specs=[dict(crosstalk=0.04, shot=0.002), dict(multiplicative=0.05), dict(drift=0.05), dict(quantization=6), dict(), dict(common_mode=0.03, saturation=1.5), dict(laplace=1.0) ]
T={"old":0.0,"new":0.0}
for sp in specs:
    try: ph = Physics.create(s=0.05, **sp)
    except Exception as e: print("skip", sp, e); continue
    ph = jax.tree_util.tree_map(lambda v: jnp.asarray(v, jnp.float32), ph)
    wt = "drift" in sp
    key=jax.random.PRNGKey(3)
    t0=time.perf_counter(); a=_measure(key, params, x, ph, arch=arch, shots=16, taps=True, with_t=wt); jax.block_until_ready(a); t1=time.perf_counter()
    b=split(key, params, x, ph, arch=arch, shots=16, taps=True, with_t=wt); jax.block_until_ready(b); t2=time.perf_counter()
    T["old"]+=t1-t0; T["new"]+=t2-t1
    la=jax.tree_util.tree_leaves(a); lb=jax.tree_util.tree_leaves(b)
    same=all(np.array_equal(np.asarray(u),np.asarray(v)) for u,v in zip(la,lb))
    print(sp, "same" if same else "DIFF", round(t1-t0,2), round(t2-t1,2), [float(np.max(np.abs(np.asarray(u)-np.asarray(v)))) for u,v in zip(la,lb)] if not same else "")
print(T)

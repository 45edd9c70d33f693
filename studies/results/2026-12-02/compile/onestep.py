import time, jax, jax.numpy as jnp, numpy as np
from functools import partial
from gift_theory import Architecture
from gift_theory.effects import Physics
from gift_theory._model import site_laws, site_draws, layer_step, noisy_input
from gift_theory.lab._shots import _one_step
import re
@partial(jax.jit, static_argnames=("arch", "layer", "q"))
def _lazy(key, W, b, a, physics, t, arch, layer, q):
    shape = a.shape[:2]
    keep = lambda n: int(re.sub(r"\D", "", n) or -1) == layer or (layer == 1 and n == "a0")
    noise = {n: site_draws(key, n, shape + tuple(ev), law, jnp.float32) for n, (ev, law) in site_laws(arch, physics).items() if keep(n)}
    if layer == 1: a = noisy_input(a, noise, physics)
    return layer_step(W, b, a, noise, physics, arch, layer, t=t)[0]
arch = Architecture((16,32,16,8)); rng=np.random.default_rng(0)
T={"full":0,"lazy":0}
for sp in [dict(crosstalk=0.04, shot=0.002), dict(multiplicative=0.05), dict(), dict(common_mode=0.03, saturation=1.5)]:
  ph = jax.tree_util.tree_map(lambda v: np.asarray(v, np.float32), Physics.create(s=0.05, **sp))
  for layer in (1,2,3):
    din, dout = arch.widths[layer-1], arch.widths[layer]
    W = jnp.asarray(rng.normal(size=(dout,din)), jnp.float32); b=jnp.zeros(dout, jnp.float32)
    a = jnp.asarray(rng.normal(size=(60,16,din)), jnp.float32)
    key=jax.random.PRNGKey(1)
    t0=time.perf_counter(); u=_one_step(key,W,b,a,ph,None,arch,layer,0).block_until_ready(); t1=time.perf_counter()
    v=_lazy(key,W,b,a,ph,None,arch,layer,0).block_until_ready(); t2=time.perf_counter()
    T["full"]+=t1-t0; T["lazy"]+=t2-t1
    print(sp, layer, np.array_equal(np.asarray(u),np.asarray(v)), round(t1-t0,2), round(t2-t1,2))
print(T)

import jax, jax.numpy as jnp, numpy as np
from gift_theory import Architecture
from gift_theory.effects import Physics
from gift_theory._model import compiled_draws, _whole_draws
n=0
for arch in (Architecture((16,32,16,8)), Architecture((5,3))):
  specs=[dict(crosstalk=0.04, shot=0.002), dict(multiplicative=0.05), dict(drift=0.05), dict(), dict(common_mode=0.03, saturation=1.5), dict(laplace={}), dict(uniform={}), dict(quantization=dict(bits=6, v_range=2.0))]
  for dt in (jnp.float32, jnp.float64):
    for shape in [(60,16), (7,3,5)]:
      for sp in specs:
        ph = Physics.create(s=0.05, **sp)
        key=jax.random.PRNGKey(3)
        a=compiled_draws(key, ph, arch=arch, shape=shape, dtype=dt); b=_whole_draws(key, ph, arch=arch, shape=shape, dtype=dt)
        assert a.keys()==b.keys() and all(np.array_equal(np.asarray(a[k]), np.asarray(b[k])) and a[k].dtype==b[k].dtype for k in a), (sp, shape, dt)
        n+=1
print("same", n)

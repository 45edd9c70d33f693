import jax, jax.numpy as jnp, numpy as np, math
from gift_theory import _model as M, _random as R
from gift_theory.effects import REGISTRY
key = jax.random.PRNGKey(5)
laws = [None, REGISTRY["laplace"](), REGISTRY["uniform"]()]
bad = 0
for x64 in (False, True):
    with jax.enable_x64(x64):
        for shape in [(1,), (1,1), (3,), (13,7,3), (40,8,5), (41,8,5), (160,96,16), (80,48,4,8), (1024,), (1025,), (1537,), (2,2049)]:
            for law in laws:
                for name in ("a0", "w2", "a1"):
                    a = np.asarray(M.compiled_site_draws(key, name, shape, law))
                    b = np.asarray(M._site_program(key, np.uint32(M.name_tag(name)), shape, law, jnp.float32))
                    if a.shape != b.shape or a.dtype != b.dtype or not np.array_equal(a.view(np.uint32), b.view(np.uint32)):
                        bad += 1; print("DIFF", x64, shape, law, name)
print("bad", bad, [R.padded_size(n) for n in (1, 1024, 1025, 1536, 1537, 2048, 2049, 3073, 2**22, 2**22+1)])

import sys, numpy as np, jax
from scipy import stats, optimize
from gift_theory.lab import load_measurement
from gift_theory.lab._shots import Model
from gift_theory.lab._offset_kinds import kinds_of
from gift_theory.lab._offset_null import _output_jacobian, _mean_output
from gift_theory.lab._offset_fit import _joint_setup
from gift_theory.lab._shots import params32
from gift_theory._model import named_subkey
import gift_theory as gt
import jax.numpy as jnp

def marg(J, rw, groups, e2):
    # rw: whitened residual (N,), J whitened (N, P); cov = I + J D J^T, D = e2[group]
    d = e2[groups]
    A = np.eye(J.shape[1]) + (np.sqrt(d)[:, None] * JtJ_g[0] * np.sqrt(d)[None, :])
    c = np.linalg.cholesky(A)
    logdet = 2 * np.sum(np.log(np.diag(c)))
    u = np.sqrt(d) * Jtr_g[0]
    v = np.linalg.solve(c, u)
    quad = rr_g[0] - v @ v
    return -0.5 * (logdet + quad)

for f in sys.argv[1:]:
    meas = load_measurement(f)
    s = float(np.sqrt(np.mean(np.var(meas.y, axis=1))))  # not used
    phys = gt.Physics.create(s=0.05).with_effect("weight_error", e=0.05) if False else None
    base = Model(gt.Physics.create(s=0.05))
    model = Model(gt.Physics.create(s=0.05), offsets={"weight_error": 0.05})
    kinds = kinds_of(["weight_error"], meas.arch)
    J, inv_v = _output_jacobian(jax.random.PRNGKey(1), meas, model, kinds)
    key = jax.random.PRNGKey(1)
    _, noise, t, _, _ = _joint_setup(named_subkey(key, "jacobian"), meas, model.physics)
    out = _mean_output(params32(base.weights(meas)), jnp.asarray(meas.x, jnp.float32), noise, base.physics, t, meas.arch)
    r0 = np.mean(meas.layers()[-1], axis=1).ravel() - np.asarray(out, np.float64).ravel()
    Jw, rw = J * np.sqrt(inv_v), r0 * np.sqrt(inv_v)
    k = kinds[0]
    sizes = [int(np.prod(k.shape(meas.arch, l))) for l in k.layers]
    groups = np.concatenate([np.full(sz, i) for i, sz in enumerate(sizes)])
    JtJ_g = [Jw.T @ Jw]; Jtr_g = [Jw.T @ rw]; rr_g = [rw @ rw]
    L = len(sizes)
    f1 = lambda le: -marg(Jw, rw, groups, np.full(L, np.exp(le[0])))
    r1 = optimize.minimize(f1, [np.log(0.003)], method="Nelder-Mead")
    fL = lambda le: -marg(Jw, rw, groups, np.exp(np.clip(le, -30, 5)))
    best = None
    for st in [np.full(L, r1.x[0])] + [np.where(np.arange(L) == i, r1.x[0], -20.0) for i in range(L)]:
        rL = optimize.minimize(fL, st, method="Nelder-Mead", options={"maxiter": 4000, "xatol": 1e-4, "fatol": 1e-6})
        if best is None or rL.fun < best.fun: best = rL
    lr = 2 * (r1.fun - best.fun)
    p = stats.chi2.sf(max(lr, 0), L - 1)
    print(f.split("/")[-2:], "e common", round(float(np.sqrt(np.exp(r1.x[0]))), 4), "e per layer", np.round(np.sqrt(np.exp(best.x)), 4), "LR", round(lr, 2), "p", f"{p:.3g}", flush=True)

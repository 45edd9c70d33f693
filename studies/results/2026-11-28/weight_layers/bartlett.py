import sys, json, numpy as np, jax
from scipy import stats
from gift_theory.lab import load_measurement, fit_effects
from gift_theory.lab._offset_kinds import kinds_of, base_model
from gift_theory.lab._offset_fit import offset_deltas
from gift_theory.lab._offset_null import _output_jacobian

def bartlett(ss, tr1, tr2):
    # per layer: |E_l|^2 ~ e^2 g chi2(nu), g = tr2/tr1, nu = tr1^2/tr2 (Satterthwaite)
    nu = tr1 ** 2 / tr2
    s2 = ss / tr1
    N = nu.sum(); sp = np.sum(nu * s2) / N
    M = N * np.log(sp) - np.sum(nu * np.log(s2))
    C = 1 + (np.sum(1 / nu) - 1 / N) / (3 * (len(nu) - 1))
    return M / C, stats.chi2.sf(M / C, len(nu) - 1), nu, s2

for f in sys.argv[1:]:
    meas = load_measurement(f)
    fit = fit_effects(jax.random.PRNGKey(0), meas, ["weight_error"])
    model = fit.after
    kinds = kinds_of(list(model.offsets), meas.arch)
    deltas = offset_deltas(model, base_model(model, meas), meas, kinds)
    k = kinds[0]
    Es = deltas[k]
    e = float(model.offsets["weight_error"])
    J, inv_v = _output_jacobian(jax.random.PRNGKey(1), meas, model, kinds)
    Js = J * e * np.sqrt(inv_v)
    U, sv, Vt = np.linalg.svd(Js, full_matrices=False)
    lam = sv ** 2
    H = (Vt.T * (lam / (lam + 1))) @ Vt
    sizes = [E.size for E in Es]
    idx = np.cumsum([0] + sizes)
    ss = np.array([np.sum(np.asarray(E) ** 2) for E in Es]) / e ** 2
    tr1 = np.array([np.trace(H[idx[i]:idx[i+1], idx[i]:idx[i+1]]) for i in range(len(Es))])
    tr2 = np.array([np.sum(H[idx[i]:idx[i+1], idx[i]:idx[i+1]] ** 2) for i in range(len(Es))])
    B, p, nu, s2 = bartlett(ss, tr1, tr2)
    print(f.split("h29/")[-1], "e", round(e, 4), "p_fit", round(fit.comparison_after.p_value, 3), "layers", k.layers, "ss", np.round(ss, 1), "dof", np.round(tr1, 1), "nu", np.round(nu, 1), "ratio", np.round(s2, 3), "Bartlett", round(B, 2), "p", f"{p:.3g}", flush=True)

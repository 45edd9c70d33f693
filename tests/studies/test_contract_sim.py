"""gift's forward pass against the independent simulator of the studies, in distribution.

``studies.contract_sim`` is a plain-numpy transcription of CONTRACTS §2 written from the
contract's text; ``gift_theory.simulate`` is gift's own (public API). For every built-in
effect both simulate the same small network on the same inputs (and, for drift, the same
acquisition times) with independent draws, and every cell -- (input, output value) over all
layers' outputs -- is compared: its mean, its variance, the covariance of every pair of
values of one shot (common_mode's sharing, the propagation between layers) and, for the
noise laws, the kurtosis. Each statistic's standard error comes from its per-shot influence
values (delta method), z = difference / sqrt(se_a^2 + se_b^2), and the test fails when any
|z| exceeds the two-sided Bonferroni bound for a familywise level of 1e-4 per effect.
weight_error is a device draw: its offsets are recovered from noiseless shots and checked
against the contract (fixed per device, iid N(0, e^2), independent across devices and layers).
Negative controls show that the comparison sees a 20 % change of a parameter.
"""

import jax
import numpy as np
import pytest
from scipy import stats

import gift_theory as gt
from studies.contract_sim import CATALOGUE, simulate_contract

ALPHA = 1e-4          # familywise level per effect (Bonferroni over cells and statistics)
WIDTHS = (3, 4, 4, 2)
N_INPUTS, SHOTS, S = 4, 20000, 0.1

#: strong settings (so a disagreement would show) of every built-in effect but weight_error
SETTINGS = {
    "awgn": {}, "laplace": {}, "uniform": {},
    "multiplicative": {"m": 0.3}, "common_mode": {"c": 0.3}, "drift": {"r": 0.8}, "crosstalk": {"k": 0.3},
    "shot": {"q": 0.05}, "saturation": {"v_max": 0.5}, "quantization": {"bits": 4.0, "v_range": 1.0},
    "layer_gain": {"g": [0.6, 1.3, 0.8]},
}


def _needs_gift(name):
    """CONTRACTS §2 names ahead of gift (added to the contract, not yet implemented) skip gift's side."""
    from gift_theory.effects import REGISTRY

    if name not in REGISTRY:
        pytest.skip(f"gift has no {name!r} yet (CONTRACTS §2, 2026-11-25)")


def _network(rng):
    Ws = [rng.normal(0.0, 1.5 / np.sqrt(WIDTHS[l]), (WIDTHS[l + 1], WIDTHS[l])) for l in range(len(WIDTHS) - 1)]
    bs = [rng.normal(0.0, 0.3, WIDTHS[l + 1]) for l in range(len(WIDTHS) - 1)]
    return Ws, bs


def _gift(seed, Ws, bs, x, t, name, params, shots=SHOTS):
    """gift's outputs of every layer, concatenated: (n, shots, d_1 + .. + d_L)."""
    arch = gt.Architecture(WIDTHS)
    arrays = {f"W{l}": W for l, W in enumerate(Ws, 1)} | {f"b{l}": b for l, b in enumerate(bs, 1)}
    if name == "layer_gain":  # gift holds a per-layer value as a (1,)-array per layer
        params = {"g": tuple((float(g),) for g in params["g"])}
    kw = {} if name == "awgn" else {name: params or True}
    physics = gt.Physics.create(s=S, **kw)
    out = gt.simulate(jax.random.PRNGKey(seed), gt.params_from_arrays(arrays), x, physics, arch, shots, t=t, taps=True)
    return np.concatenate([np.asarray(a, np.float64) for a in out.taps], axis=-1)


def _contract(seed, Ws, bs, x, t, name, params, shots=SHOTS):
    """The independent simulator's outputs of every layer, concatenated like :func:`_gift`."""
    effects = {} if name == "awgn" else {name: params}
    y, taps, _ = simulate_contract(np.random.default_rng(seed), WIDTHS, Ws, bs, x, shots, S, effects, t=t)
    return np.concatenate(taps + [y], axis=-1)


def cell_statistics(Y, shape: bool):
    """Per-cell statistics of Y (n, R, D) over its R shots and their standard errors.

    Returns {name: (value, se)}: mean and variance (n, D), covariance of each pair of values
    (n, D (D - 1) / 2), and with ``shape`` the kurtosis m4 / m2^2 (n, D). Standard errors are
    the standard deviation of the per-shot influence values over sqrt(R).
    """
    R = Y.shape[1]
    c = Y - Y.mean(axis=1, keepdims=True)
    v = (c ** 2).mean(axis=1)
    out = {"mean": (Y.mean(axis=1), c.std(axis=1) / np.sqrt(R)),
           "variance": (v, (c ** 2).std(axis=1) / np.sqrt(R))}
    i, j = np.triu_indices(Y.shape[2], 1)
    prod = c[:, :, i] * c[:, :, j]
    out["covariance"] = (prod.mean(axis=1), prod.std(axis=1) / np.sqrt(R))
    if shape:
        m3, m4 = (c ** 3).mean(axis=1), (c ** 4).mean(axis=1)
        infl = ((c ** 4 - m4[:, None]) / v[:, None] ** 2 - 2 * m4[:, None] / v[:, None] ** 3 * (c ** 2 - v[:, None])
                - 4 * m3[:, None] / v[:, None] ** 2 * c)
        out["kurtosis"] = (m4 / v ** 2, infl.std(axis=1) / np.sqrt(R))
    return out


def agreement(A, B, shape: bool):
    """(largest |z| over all cells and statistics, the Bonferroni bound at ALPHA, the worst cell)."""
    sa, sb = cell_statistics(A, shape), cell_statistics(B, shape)
    zs = {}
    for name in sa:
        diff = sa[name][0] - sb[name][0]
        se = np.sqrt(sa[name][1] ** 2 + sb[name][1] ** 2)
        zs[name] = np.where(se > 0, np.abs(diff) / np.where(se > 0, se, 1.0), np.where(diff == 0, 0.0, np.inf))
    m = sum(z.size for z in zs.values())
    bound = stats.norm.isf(ALPHA / (2 * m))
    worst = max(zs, key=lambda k: zs[k].max())
    return float(zs[worst].max()), float(bound), f"{worst} at {np.unravel_index(zs[worst].argmax(), zs[worst].shape)}"


def _setting():
    seed = np.random.randint(2 ** 31)
    rng = np.random.default_rng(seed)
    Ws, bs = _network(rng)
    x = rng.normal(0.0, 1.0, (N_INPUTS, WIDTHS[0]))
    t = rng.uniform(0.0, 1.0, (N_INPUTS, SHOTS))
    return seed, Ws, bs, x, t


def test_the_study_names_every_builtin_effect():
    """Every name of gift's catalogue is in the contract's (the contract may be ahead of gift)."""
    assert set(SETTINGS) | {"weight_error"} == set(CATALOGUE) >= set(gt.EFFECT_NAMES)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_builtin_effect_agrees_in_distribution(name):
    _needs_gift(name)
    seed, Ws, bs, x, t = _setting()
    A = _gift(seed, Ws, bs, x, t, name, SETTINGS[name])
    B = _contract(seed + 1, Ws, bs, x, t, name, SETTINGS[name])
    z, bound, where = agreement(A, B, shape=name in ("awgn", "laplace", "uniform"))
    assert z < bound, f"{name}: gift and the contract's transcription disagree, |z| = {z:.2f} > {bound:.2f} ({where})"


@pytest.mark.parametrize("name, changed", [
    ("laplace", ("awgn", {})),                       # the law's shape at equal variance
    ("multiplicative", ("multiplicative", {"m": 0.24})),
    ("common_mode", ("multiplicative", {"m": 0.3})),  # shared vs per-neuron gains: the covariances
    ("crosstalk", ("crosstalk", {"k": 0.24})),
    ("saturation", ("saturation", {"v_max": 0.6})),
])
def test_the_comparison_sees_a_changed_effect(name, changed):
    """Negative controls: the same statistics flag a 20 % change of the parameter or a different effect."""
    seed, Ws, bs, x, t = _setting()
    A = _gift(seed, Ws, bs, x, t, name, SETTINGS[name])
    B = _contract(seed + 1, Ws, bs, x, t, changed[0], changed[1])
    z, bound, _ = agreement(A, B, shape=True)
    assert z > bound, f"{name} against {changed}: |z| = {z:.2f} only (bound {bound:.2f})"


def _recover_offsets(Ws, bs, x, taps):
    """E_l = W_l^eff - W_l from noiseless outputs: z_1 = arctanh(a_1), then least squares per layer."""
    E, a_prev = [], x
    for l, (W, b) in enumerate(zip(Ws, bs)):
        z = np.arctanh(taps[l]) if l < len(Ws) - 1 else taps[l]
        E.append(np.linalg.lstsq(a_prev, z - a_prev @ W.T - b, rcond=None)[0].T)
        a_prev = taps[l]
    return E


@pytest.mark.slow
def test_weight_error_is_a_fixed_iid_gaussian_offset_per_device(x64):
    """CONTRACTS §2: W_eff = W + E, E iid N(0, e^2), drawn once per device and fixed."""
    widths, e, devices = (12, 12, 12), 0.1, 6
    rng = np.random.default_rng(np.random.randint(2 ** 31))
    Ws = [rng.normal(0.0, 0.4 / np.sqrt(12), (12, 12)) for _ in range(2)]
    bs = [rng.normal(0.0, 0.1, 12) for _ in range(2)]
    x = rng.normal(0.0, 1.0, (30, 12))
    arrays = {"W1": Ws[0], "W2": Ws[1], "b1": bs[0], "b2": bs[1]}
    arch, params = gt.Architecture(widths), gt.params_from_arrays(arrays)

    # the recovery itself, on the independent simulator whose offsets are known (t given: E are its first draws)
    seed = int(rng.integers(2 ** 31))
    y, taps, _ = simulate_contract(np.random.default_rng(seed), widths, Ws, bs, x, 1, 0.0, {"weight_error": {"e": e}},
                                   t=np.zeros((30, 1)))
    replay = np.random.default_rng(seed)
    known = [replay.normal(0.0, e, W.shape) for W in Ws]
    for got, want in zip(_recover_offsets(Ws, bs, x, [taps[0][:, 0], y[:, 0]]), known):
        np.testing.assert_allclose(got, want, atol=1e-9)

    offsets = []
    for device in range(devices):
        physics = gt.Physics.create(s=0.0, weight_error={"e": e, "seed": device})  # s=None returns one shot
        runs = [gt.simulate(jax.random.PRNGKey(k), params, x, physics, arch, 2, taps=True) for k in (0, 1)]
        per_shot = [_recover_offsets(Ws, bs, x, [np.asarray(a)[:, shot] for a in run.taps]) for run in runs
                    for shot in (0, 1)]
        for other in per_shot[1:]:  # fixed for the device: the same offsets in every shot and every call
            for a, b in zip(per_shot[0], other):
                np.testing.assert_allclose(a, b, atol=1e-9)
        offsets.append(np.stack(per_shot[0]))  # (layers, 12, 12)
    E = np.stack(offsets)                        # (devices, layers, 12, 12)
    flat = E.reshape(devices * 2, -1)            # one row per (device, layer)
    N = E.size
    tests = {  # two-sided p-values, Bonferroni over the family below
        "mean 0": 2 * stats.norm.sf(abs(E.sum()) / (e * np.sqrt(N))),
        "variance e^2": 2 * min(stats.chi2.cdf((E ** 2).sum() / e ** 2, N), stats.chi2.sf((E ** 2).sum() / e ** 2, N)),
        "kurtosis 3": 2 * stats.norm.sf(abs(np.mean(E ** 4) / np.mean(E ** 2) ** 2 - 3) / np.sqrt(24 / N)),
        "independent of W": 2 * stats.norm.sf(abs(np.corrcoef(E.reshape(devices, -1).ravel(),
                                                               np.tile(np.ravel(Ws), devices))[0, 1]) * np.sqrt(N)),
    }
    corr = np.corrcoef(flat)[np.triu_indices(len(flat), 1)]  # across devices and across layers
    tests["independent rows (worst pair)"] = min(1.0, len(corr) * 2 * stats.norm.sf(np.abs(corr).max() * np.sqrt(flat.shape[1])))
    bad = {k: p for k, p in tests.items() if p < ALPHA / len(tests)}
    assert not bad, f"gift's weight_error offsets break CONTRACTS §2: {bad}"


# ------------------------------------------------- the open physics do what their definitions say

def _open_net(rng, widths=(5, 7, 6, 3)):
    Ws = [rng.normal(0.0, 1.2 / np.sqrt(widths[l]), (widths[l + 1], widths[l])) for l in range(len(widths) - 1)]
    bs = [rng.normal(0.0, 0.3, widths[l + 1]) for l in range(len(widths) - 1)]
    return list(widths), Ws, bs, rng.normal(0.0, 1.0, (6, widths[0]))


def _noiseless(widths, Ws, bs, x, act=np.tanh, kappa=1.0, a2=0.0, Weff=None, delta=None, square=False,
              dead=None, det=None):
    """The stated formulas, one layer at a time, without noise: [a_1 .. a_L].

    dead : (layer, neuron) whose activation is 0; det : (gains, offsets) per layer applied to each output
    """
    outs, a = [], x
    for l, (W, b) in enumerate(zip(Ws, bs)):
        z = a @ (W if Weff is None else Weff[l]).T + b + (0.0 if delta is None else delta[l])
        if l < len(Ws) - 1:
            h = act(kappa * z)
            a = h + a2 * h ** 2
            if dead is not None and dead[0] == l + 1:
                a[..., dead[1]] = 0.0
        else:
            a = z ** 2 if square else z
        if det is not None:
            a = det[0][l] * a + det[1][l]
        outs.append(a)
    return outs


def test_open_physics_at_zero_strength_draw_nothing_and_change_nothing():
    """An effect draws from the generator only when present: at zero strength the output is the
    plain model's, draw for draw (what keeps the built-in study's files byte-identical)."""
    rng = np.random.default_rng(np.random.randint(2 ** 31))
    widths, Ws, bs, x = _open_net(rng)
    zero = {"activation_gain": {"kappa": 1.0}, "activation_shape": {"a2": 0.0}, "signal_noise": {"beta": 0.0},
            "dense_crosstalk": {"k": 0.0, "C": [np.ones((d, d)) for d in widths[:-1]]},
            "bias_offset": {"delta": [np.zeros(d) for d in widths[1:]]}}
    plain = simulate_contract(np.random.default_rng(7), widths, Ws, bs, x, 5, 0.1, {})
    for name, params in zero.items():
        got = simulate_contract(np.random.default_rng(7), widths, Ws, bs, x, 5, 0.1, {name: params})
        np.testing.assert_array_equal(got[0], plain[0], err_msg=name)


def test_open_physics_follow_their_formulas_without_noise():
    from studies.contract_sim import OPEN_PHYSICS

    rng = np.random.default_rng(np.random.randint(2 ** 31))
    widths, Ws, bs, x = _open_net(rng)
    L = len(Ws)
    for name, spec in OPEN_PHYSICS.items():
        if name in ("signal_noise", "ar1_gain", "common_noise", "student_t_layer"):
            continue  # noise effects: statistical checks below
        p = spec.draw(rng, widths, 6, 1)
        t = np.full((6, 1), 0.7)
        y, taps, _ = simulate_contract(np.random.default_rng(0), widths, Ws, bs, x, 1, 0.0, {name: p}, t=t)
        kw = {"activation_gain": lambda: {"kappa": p["kappa"]}, "activation_shape": lambda: {"a2": p["a2"]},
              "bias_offset": lambda: {"delta": p["delta"]}, "square_law": lambda: {"square": True},
              "dense_crosstalk": lambda: {"Weff": [W + p["k"] * W @ C for W, C in zip(Ws, p["C"])]},
              "sin_modulator": lambda: {"act": np.sin},
              "bias_drift": lambda: {"delta": [np.full(d, p["c"] * 0.7 if l == 0 else 0.0)
                                               for l, d in enumerate(widths[1:])]},
              "dead_neuron": lambda: {"dead": (p["layer"], p["neuron"])},
              "detector_gain_offset": lambda: {"det": (p["gain"], p["offset"])},
              "last_layer_weight_error": lambda: {"Weff": Ws[:-1] + [Ws[-1] + p["E"]]}}[name]()
        want = _noiseless(widths, Ws, bs, x, **kw)
        for got, w in zip(taps + [y], want):
            np.testing.assert_allclose(got[:, 0], w, rtol=1e-12, atol=1e-12, err_msg=name)
        # where it acts: the layers whose one-step map (fed the true previous output) differs from the model's
        plain = _noiseless(widths, Ws, bs, x)
        fed = [np.tanh(a @ W.T + b) if l < L - 1 else a @ W.T + b
               for l, (a, W, b) in enumerate(zip([x] + want[:-1], Ws, bs))]
        acts = [l + 1 for l in range(L) if not np.allclose(fed[l], want[l], atol=1e-9)]
        assert acts == spec.layers(L, p), (name, acts)
        assert plain is not None
    C = OPEN_PHYSICS["dense_crosstalk"].draw(rng, widths, 6, 1)["C"]
    for c in C:
        j, m = np.indices(c.shape)
        assert np.all(c[np.abs(j - m) < 2] == 0) and np.all(c[np.abs(j - m) >= 2] != 0)


def test_signal_noise_sd_grows_with_the_signal_on_hidden_layers_only():
    """Identity activation, zero output weights: a_1 = u + s (1 + beta |u|) n_w + s n_a with
    u = W_1 (x + s n_a0), and y = n_wL alone (variance s^2: the output layer keeps s). The
    simulator's per-cell variances against a 10^6-draw transcription of that formula, with
    the standard error of each variance from its per-shot values (5 sigma, Bonferroni-safe for 8 cells)."""
    s, beta, R = 0.1, 2.0, 40000
    W1 = np.array([[1.0, 0.0], [-2.0, 0.5], [0.0, 0.0]])
    x = np.array([[0.5, -1.0], [1.0, 0.3]])
    Ws, bs = [W1, np.zeros((1, 3))], [np.zeros(3), np.zeros(1)]
    rng = np.random.default_rng(np.random.randint(2 ** 31))
    y, taps, _ = simulate_contract(rng, [2, 3, 1], Ws, bs, x, R, s, {"signal_noise": {"beta": beta}},
                                   activation=lambda z: z)
    ref = np.random.default_rng(rng.integers(2 ** 31))
    u = (x[:, None, :] + s * ref.standard_normal((2, 10 ** 6, 2))) @ W1.T
    a1 = u + s * (1 + beta * np.abs(u)) * ref.standard_normal(u.shape) + s * ref.standard_normal(u.shape)
    got = np.concatenate([taps[0], y], axis=-1)
    want = np.concatenate([a1.var(axis=1), np.full((2, 1), s ** 2)], axis=-1)
    c2 = (got - got.mean(axis=1, keepdims=True)) ** 2
    z = (c2.mean(axis=1) - want) / (c2.std(axis=1) / np.sqrt(R))
    assert np.all(np.abs(z) < 5), z
    assert np.all(want[:, :2] > 2 * (W1[:2, 0] ** 2 + W1[:2, 1] ** 2 + 2) * s ** 2)  # beta visibly adds variance


def test_ar1_path_has_unit_variance_and_its_lag_correlation():
    from studies.contract_sim import ar1_path

    tau, N = 20.0, 200000
    xi = ar1_path(np.random.default_rng(np.random.randint(2 ** 31)), N, tau)
    rho = np.exp(-1 / tau)
    n_eff = N * (1 - rho ** 2) / (1 + rho ** 2)  # for the variance of an AR(1)'s sample variance
    assert abs(xi.var() - 1) < 5 * np.sqrt(2 / n_eff)
    lag = np.corrcoef(xi[:-1], xi[1:])[0, 1]
    assert abs(lag - rho) < 5 * np.sqrt((1 - rho ** 2) / N)  # Bartlett's standard error of the lag-1 estimate


def test_common_noise_is_shared_by_the_neurons_of_a_layer():
    """Zero weights and biases, identity activation: a_1 = n_w + c xi + n_a, so two neurons of
    layer 1 have covariance c^2 and each has variance 2 s^2 + c^2 (5 standard errors; Bonferroni-safe
    for these 9 cells)."""
    s, c, R = 0.1, 0.15, 40000
    Ws, bs = [np.zeros((3, 2)), np.zeros((1, 3))], [np.zeros(3), np.zeros(1)]
    x = np.zeros((1, 2))
    y, taps, _ = simulate_contract(np.random.default_rng(np.random.randint(2 ** 31)), [2, 3, 1], Ws, bs, x, R, s,
                                   {"common_noise": {"c": c}}, activation=lambda z: z)
    a = taps[0][0]                                       # (R, 3)
    i, j = np.triu_indices(3, 1)
    prod = a[:, i] * a[:, j]
    z_cov = (prod.mean(0) - c ** 2) / (prod.std(0) / np.sqrt(R))
    z_var = ((a ** 2).mean(0) - (2 * s ** 2 + c ** 2)) / ((a ** 2).std(0) / np.sqrt(R))
    assert np.all(np.abs(z_cov) < 5) and np.all(np.abs(z_var) < 5), (z_cov, z_var)
    yv = y[0, :, 0]                                      # the output layer: its own xi, s^2 + c^2
    assert abs((yv ** 2).mean() - (s ** 2 + c ** 2)) < 5 * (yv ** 2).std() / np.sqrt(R)


def test_student_t_noise_acts_in_its_layer_only():
    """Zero weights, identity activation: layer 1's values are Gaussian (kurtosis 3), layer 2's
    (the output, n_w2 alone) Student-t with nu = 6 (kurtosis 3 + 6 / (nu - 4) = 6), both of
    standard deviation s in the output and sqrt(2) s in layer 1."""
    s, nu, R = 0.1, 6.0, 200000
    Ws, bs = [np.zeros((2, 2)), np.zeros((1, 2))], [np.zeros(2), np.zeros(1)]
    y, taps, _ = simulate_contract(np.random.default_rng(np.random.randint(2 ** 31)), [2, 2, 1], Ws, bs,
                                   np.zeros((1, 2)), R, s, {"student_t_layer": {"nu": nu, "layer": 2}},
                                   activation=lambda z: z)
    a1, yv = taps[0][0], y[0, :, 0]
    kurt = lambda v: np.mean(v ** 4) / np.mean(v ** 2) ** 2  # noqa: E731
    assert np.all(np.abs([kurt(a1[:, k]) - 3 for k in range(2)]) < 5 * np.sqrt(24 / R))
    # standard errors of a sample standard deviation: sd sqrt((kurtosis - 1) / (4 R))
    assert kurt(yv) > 3 + 1.5 and abs(yv.std() - s) < 5 * s * np.sqrt((6 - 1) / (4 * R))
    assert np.all(np.abs(a1.std(0) - np.sqrt(2) * s) < 5 * np.sqrt(2) * s * np.sqrt(2 / (4 * R)))

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
}


def _network(rng):
    Ws = [rng.normal(0.0, 1.5 / np.sqrt(WIDTHS[l]), (WIDTHS[l + 1], WIDTHS[l])) for l in range(len(WIDTHS) - 1)]
    bs = [rng.normal(0.0, 0.3, WIDTHS[l + 1]) for l in range(len(WIDTHS) - 1)]
    return Ws, bs


def _gift(seed, Ws, bs, x, t, name, params, shots=SHOTS):
    """gift's outputs of every layer, concatenated: (n, shots, d_1 + .. + d_L)."""
    arch = gt.Architecture(WIDTHS)
    arrays = {f"W{l}": W for l, W in enumerate(Ws, 1)} | {f"b{l}": b for l, b in enumerate(bs, 1)}
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
    assert set(SETTINGS) | {"weight_error"} == set(CATALOGUE) == set(gt.EFFECT_NAMES)


@pytest.mark.parametrize("name", sorted(SETTINGS))
def test_builtin_effect_agrees_in_distribution(name):
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

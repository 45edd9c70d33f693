"""linear_case: closed forms against autodiff, sympy and the generic Monte-Carlo model."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import sympy as sp
from hypothesis import given
from hypothesis import strategies as st

import gift_theory as gt
import linear_case as lc


def _random_ws(rng, widths):
    return tuple(rng.normal(size=(widths[l], widths[l - 1])) * 0.7 for l in range(1, len(widths)))


def test_J_matches_monte_carlo_both_placements(x64):
    rng = np.random.default_rng(0)
    widths = (3, 2, 2)
    ws = _random_ws(rng, widths)
    V = rng.normal(size=(2, 3))
    task = lc.LinearTask(V, np.eye(3))
    kx, kn = jax.random.split(jax.random.PRNGKey(1))
    x = jax.random.normal(kx, (8192, 3), jnp.float64)
    y = x @ jnp.asarray(V).T
    params = tuple(gt.Layer(jnp.asarray(W), jnp.zeros((W.shape[0],))) for W in ws)
    for mode in lc.MODES:
        arch = gt.Architecture(widths, activation="identity", noise_sites=mode)
        est = gt.objective(kn, params, x, y, gt.awgn(0.4), arch, K2=4)
        closed = float(lc.J(tuple(jnp.asarray(W) for W in ws), 0.4, task, mode))
        assert abs(float(est.mean) - closed) < 4.5 * float(est.se), (mode, est, closed)


@pytest.mark.slow
def test_s_derivatives_are_2s_gradB_and_2_gradB(x64):
    rng = np.random.default_rng(2)
    ws = tuple(jnp.asarray(W) for W in _random_ws(rng, (2, 3, 1)))
    task = lc.isotropic_task(rng.normal(size=(1, 2)), 1.3)
    for mode in lc.MODES:
        d = lc.derivatives(ws, 0.7, task, mode)
        flat = lambda t: jax.flatten_util.ravel_pytree(t)[0]
        g = lambda s: flat(jax.grad(lc.J)(ws, s, task, mode))
        np.testing.assert_allclose(d["ds_grad"], np.asarray(jax.jacfwd(g)(0.7)), rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(d["ds2_grad"], np.asarray(jax.jacfwd(jax.jacfwd(g))(0.7)), rtol=1e-10,
                                   atol=1e-12)


@given(L=st.integers(1, 4), Vn=st.floats(0.1, 3.0), m2=st.floats(0.2, 3.0), s0=st.floats(0.05, 1.5),
       st_=st.floats(0.05, 2.0))
def test_bounds_closed_forms(L, Vn, m2, s0, st_):
    task = lc.isotropic_task([[Vn, 0.0]], m2)
    ws = lc.balanced_chain(lc.product_minimiser(s0, task), L)
    d = lc.derivatives(ws, s0, task)
    assert np.max(np.abs(d["grad"])) < 1e-8 * max(1.0, np.max(np.abs(d["grad_B"])))     # w0 is critical
    b = lc.theorem1_bounds(ws, s0, task)
    assert math.isclose(b.corrected_rhs, 2 * s0, rel_tol=1e-9)
    assert math.isclose(b.printed_rhs, float(lc.chain_printed_rhs(s0, L, Vn, m2)), rel_tol=1e-8)
    if L == 1:
        assert math.isclose(b.printed_rhs, float(lc.example_rhs(s0, m2, Vn)), rel_tol=1e-8)
    gst = lc.derivatives(ws, st_, task)["grad"]
    assert math.isclose(float(gst @ d["ds_grad"]), b.C1(s0, st_), rel_tol=1e-7, abs_tol=1e-12)


def test_symbolic_example_depths():
    e1, e2 = lc.symbolic_example(1), lc.symbolic_example(2)
    assert sp.simplify(e1["printed_rhs"] - e1["example_rhs"]) == 0
    assert sp.simplify(e2["printed_rhs"] - e2["example_rhs"]) != 0
    for e in (e1, e2):
        assert sp.simplify(e["corrected_rhs"] - 2 * e["s0"]) == 0
        assert sp.simplify(e["C1"].subs(e["st"], e["s0"])) == 0
        assert all(sp.simplify(r) == 0 for r in e["critical_residual"])


def test_plots_return_figures_on_given_axes_and_leave_the_backend_alone(tmp_path):
    import matplotlib
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    backend = matplotlib.get_backend()
    fig = lc.plot_bound_regions(depths=(1, 2), V_norms=(0.5,), n=41)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    fig.savefig(tmp_path / "regions.png")               # the caller saves
    assert (tmp_path / "regions.png").stat().st_size > 1000
    own, ax = plt.subplots()
    assert lc.plot_bound_regions(depths=(2,), V_norms=(1.0,), n=41, ax=ax) is own
    assert lc.plot_example_curves(ax=ax) is own
    assert isinstance(lc.plot_example_curves(), Figure)
    with pytest.raises(ValueError, match="2 x 1"):
        lc.plot_bound_regions(depths=(2,), V_norms=(1.0, 2.0), ax=ax)
    assert matplotlib.get_backend() == backend
    plt.close("all")


def test_bound_rhs_admits_exactly_the_band_of_each_printed_and_corrected_bound():
    s0 = np.linspace(0.05, 2.0, 40)
    r = lc.bound_rhs(s0, 2, 1.0)
    assert np.allclose(r["corrected"], 2 * s0)
    assert np.allclose(r["example"], lc.example_rhs(s0, 1.0, 1.0))
    assert np.allclose(r["printed"], lc.chain_printed_rhs(s0, 2, 1.0))
    r1 = lc.bound_rhs(s0, 1, 1.5)
    assert np.allclose(r1["printed"], r1["example"])     # at depth 1 the two printed bounds agree


def test_all_noise_chain_has_only_trivial_critical_points_for_L_ge_2():
    J, sols, rescale = lc.all_noise_critical_points(1)
    assert len(sols) == 1 and sp.simplify(list(sols[0].values())[0] - sp.Symbol("V", positive=True) * sp.Symbol(
        "m2", positive=True) / (sp.Symbol("m2", positive=True) + sp.Symbol("s", positive=True) ** 2)) == 0
    J, sols, rescale = lc.all_noise_critical_points(2)
    assert sols and all(sp.Mul(*[sol.get(w, w) for w in sp.symbols("w1:3", real=True)]) == 0 for sol in sols)
    assert rescale != 0          # rescaling the factors lowers J whenever w2 != 0

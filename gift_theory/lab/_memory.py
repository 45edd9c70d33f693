"""Memory: does a layer's shot carry the shot acquired before it? (reference §6 class ``memory``.)

A detector whose response to one shot lingers into the next (finite bandwidth, thermal memory)
measures ``out_k = v_k + alpha out_{k-1}``, k the shot's rank in acquisition time over the whole
campaign (the built-in effect ``memory``). With the shots of one input acquired at random times
among the others', the previous shot belongs to another input: memory shifts each neuron's
mean by alpha times the campaign's mean output (what a per-neuron bias offset does) and adds
the spread of the previous shots' outputs to each cell's variance. Only the acquisition order
tells it from those.

**The test** (:func:`lag_test`), per measured layer, on the within-input residuals e (the
layer's shots less their input's mean; with taps, less their regression on the shot's own
input, so a memory upstream -- which the layer's input carries -- is not read here): each
residual against the previous shot's value minus the value of the shot :data:`CONTROL` places
before it, same neuron, each neuron weighted by its residuals' inverse variance::

    T = sum_k sum_i e_ki (y_{k-1,i} - y_{k-L,i}) / v_i

A memory gives the previous shot a weight alpha and the L-th alpha^L; a slow process in time
(a wandering gain, a drift) moves shots L apart as it moves neighbours and cancels in the
difference. Under the null (no memory), the shots of one input are exchangeable: their values
may be dealt to the input's acquisition times in any order. T's law under the null is read off
:data:`PERMUTATIONS` such deals (within each input, a fixed seed per layer): z is T against
their mean and standard deviation. Where z, read as normal, gives p below :data:`EXTEND_P`, the
deals go on to :data:`MORE_PERMUTATIONS` in all (unless p is below :data:`BEYOND_P`: far beyond
any deal) and p is read off the deals themselves (two-sided: a memory may be negative),
``(1 + #{|T_b - m| >= |T - m|}) / (1 + B)``; only beyond every deal is the normal tail used (at
most ``1 / (1 + B)``). The deals' law has heavier tails than a normal, so z read as normal is
liberal in the tail that decides (on null files about 2.5 % of layers below 0.01).
That null is exact whatever the noise's law and the map's misfit (both travel with the shot),
and takes care of the residuals' own correlation within an input: with the shots of an input
acquired one after the other, the previous shot is of the same input, and a within-input
residual is biased against its neighbour by -1 / r.

**Without the times** there is no order: the test is not run, and the row says so.

**The estimate** of alpha: the same partial regression (with taps the previous shots' values
less their regression on the shot's own input too), less its bias: a residual centred within
its input is biased against a neighbour of the same input by the deals' mean m (about
-1 / (r - 1) when the shots of an input are acquired one after the other), by m (1 + alpha)
under a memory, so alpha = (raw - m) / (1 + m). When the layer's memory is
named (p below :data:`UNDO_P`), the shots are read again with it taken out, exactly:
``v_k = out_k - alpha out_{k-1}`` (:func:`undo`), so the layer's map and noise are the
detector's own and the memory's mean shift is not read as bias offsets.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

#: the control lag: the shot this many acquisitions before
CONTROL = 4
#: deals of each input's shots to its acquisition times behind the null law
PERMUTATIONS = 100
#: below this p (the first deals read as normal) the deals go on to MORE_PERMUTATIONS in all and
#: p is read off them
EXTEND_P = 0.05
MORE_PERMUTATIONS = 1000
#: ... unless it is below this (|z| > 6.1): no deal of a thousand reaches such a statistic under
#: any law the deals of a sum over a campaign's shots follow, and the normal tail stands
BEYOND_P = 1e-9
#: a layer's memory is taken out of its shots (and the layer read again) below this p
UNDO_P = 1e-3
#: cosines of t (besides a line) the residuals are detrended by before the lag is read, where an
#: input's shots spread over at least this much of the campaign (sd of t within the inputs)
DETREND = 6
SPREAD = 0.05


@dataclasses.dataclass(frozen=True)
class Lag:
    """The lag test of one layer: ``row`` (the identification's row of class memory), ``alpha``
    and its standard error, ``p``; ``order`` the flat shot index (n r) in acquisition order."""

    row: dict
    alpha: float
    alpha_se: float
    p: float
    order: np.ndarray | None


def _order(t) -> np.ndarray:
    return np.argsort(np.asarray(t, np.float64).ravel(), kind="stable")


def _lagged(Yf, order, lag):
    """(N, d): each shot's value of the shot ``lag`` acquisitions before it, 0 for the first ones."""
    out = np.zeros_like(Yf)
    if lag < order.size:
        out[order[lag:]] = Yf[order[:-lag]]
    return out


def _detrended(E, Y, t):
    """Within-input residuals less, per neuron, their regression on slow functions of t (a line
    and :data:`DETREND` cosines, within-input deviations) and on the same times the input's mean
    value (a gain that drifts or wanders moves each input's shots along its mean): what a slow
    process in time leaves, a memory does not (its lag is one shot)."""
    from ._time import basis

    n, r, d = E.shape
    e = E - E.mean(1, keepdims=True)
    if float(np.std(t - t.mean(1, keepdims=True))) < SPREAD:
        # an input's shots taken one after the other: a slow process hardly moves within them,
        # and the cosines there are one short ramp, which would take a memory's transient
        return e
    B = np.concatenate([t[..., None], basis(t, DETREND)], axis=2)
    B = B - B.mean(1, keepdims=True)  # (n, r, q)
    ybar = Y.mean(1)  # (n, d)
    out = np.empty_like(e)
    Bf = B.reshape(n * r, -1)
    for i in range(d):
        X = np.concatenate([Bf, (B * ybar[:, None, i, None]).reshape(n * r, -1)], axis=1)
        beta = np.linalg.lstsq(X, e[:, :, i].ravel(), rcond=None)[0]
        out[:, :, i] = (e[:, :, i].ravel() - X @ beta).reshape(n, r)
    return out


def _coefficient(a1, aL, g11, g1L, gLL):
    """The coefficient of x1 in the regression on (x1, xL), from the cross products (x1'e, xL'e,
    x1'x1, x1'xL, xL'xL)."""
    det = g11 * gLL - g1L * g1L
    return (gLL * a1 - g1L * aL) / det if det > 0 else 0.0


def _partial(e, x1, xL, v):
    """The coefficient of x1 in the regression of e on (x1, xL), pooled over neurons weighted by 1 / v."""
    return _coefficient(float(np.sum(e * x1 / v)), float(np.sum(e * xL / v)), float(np.sum(x1 * x1 / v)),
                        float(np.sum(x1 * xL / v)), float(np.sum(xL * xL / v)))


def lag_test(layer: int, E, Y, t, row_of, g=None, A=None) -> Lag:
    """The memory test of one layer (see the module). ``E`` (n, r, d) the residuals (with taps
    less their regression on the shot's own input), ``Y`` (n, r, d) the measured shots, ``t``
    (n, r) or None; ``row_of(cls, test, p, z, effect, evidence)`` makes the row. With taps, ``g``
    (n, r, d) and ``A`` (n, r, p): the slope and the shot's own input, which the estimate of alpha
    takes out of the previous shots' values too (a memory upstream moves both)."""
    n, r, d = Y.shape
    if t is None or r < 2 or n * r <= CONTROL + 1:
        return Lag(row_of("memory", "lag", 1.0, 0.0, 0.0, f"no acquisition times: memory at layer {layer} cannot be "
                          "tested (it needs the order the shots were taken in)"), 0.0, float("inf"), 1.0, None)
    N = n * r
    e = _detrended(np.asarray(E, np.float64), np.asarray(Y, np.float64), np.asarray(t, np.float64)).reshape(N, d)
    v = np.maximum(np.sum(e * e, 0) / max(n * (r - 1), 1), 1e-300)
    Yf = np.asarray(Y, np.float64).reshape(N, d)
    order = _order(t)
    first = np.zeros(N, bool)
    first[order[:CONTROL]] = True  # shots without a full history carry no term
    # the deals' statistic on arrays scaled by 1 / sqrt(v) per neuron (every sum of _partial is
    # then a plain dot product), each shot's lagged value one gather through the slot acquired
    # ``lag`` before it (a zero row past the end for the first shots)
    w = 1.0 / np.sqrt(v)
    es, Ys = e * w, np.concatenate([Yf * w, np.zeros((1, d))])
    before = {lag: np.full(N, N) for lag in (1, CONTROL)}
    for lag, idx in before.items():
        idx[order[lag:]] = order[:-lag]

    # the deals reuse these buffers (no fresh pages per deal) and precomputed index rules
    invalid = {lag: idx >= N for lag, idx in before.items()}
    clipped = {lag: np.minimum(idx, N - 1) for lag, idx in before.items()}
    first_rows = np.flatnonzero(first)
    ep_buf, src_buf = np.empty_like(es), np.empty(N, np.intp)
    x_bufs = {lag: np.empty((n, r, d)) for lag in before}
    mean_buf = np.empty((n, 1, d))

    def stat_of(perm):
        """_partial of the deal ``perm`` (slot s holds record perm[s]; None: the campaign as taken)."""
        ep = es if perm is None else np.take(es, perm, axis=0, out=ep_buf, mode="clip")
        xs = []
        for lag in (1, CONTROL):
            if perm is None:
                src = before[lag]
            else:  # the record dealt to the slot acquired ``lag`` before (N: none)
                src = np.take(perm, clipped[lag], out=src_buf, mode="clip")
                np.copyto(src, N, where=invalid[lag])
            x = x_bufs[lag]
            np.take(Ys, src, axis=0, out=x.reshape(N, d), mode="clip")
            np.subtract(x, x.mean(1, keepdims=True, out=mean_buf), out=x)
            x = x.reshape(N, d)
            x[first_rows] = 0.0
            xs.append(x)
        x1, xL = xs
        return _coefficient(float(np.vdot(ep, x1)), float(np.vdot(ep, xL)), float(np.vdot(x1, x1)),
                            float(np.vdot(x1, xL)), float(np.vdot(xL, xL)))

    stat = stat_of(None)
    # deals of each input's shots to its times: within each input a random permutation of its r shots
    rng = np.random.default_rng([48, int(layer), n, r, d])
    base = (np.arange(n) * r)[:, None]

    def deals(count):
        out = np.empty(count)
        for b in range(count):
            perm = (base + rng.permuted(np.broadcast_to(np.arange(r), (n, r)), axis=1)).ravel()
            # a deal moves each shot's whole record: its residual and its value (the lagged
            # values are those of the shots dealt to the earlier times)
            out[b] = stat_of(perm)
        return out

    null = deals(PERMUTATIONS)
    m, sd = float(null.mean()), float(null.std(ddof=1))
    z = (stat - m) / sd if sd > 0 else 0.0
    p = float(min(1.0, 2.0 * stats.norm.sf(abs(z))))
    if BEYOND_P <= p < EXTEND_P:  # (z != 0 here, so the deals spread: sd > 0 with more of them too)
        null = np.concatenate([null, deals(MORE_PERMUTATIONS - PERMUTATIONS)])
        m, sd = float(null.mean()), float(null.std(ddof=1))
        z = (stat - m) / sd
        p = deals_p(null, stat, m, z)
    # the estimate: the same partial regression, the previous shots' values less (with taps) their
    # regression on the shot's own input too; its null mean (the residual's bias against a
    # neighbour of the same input, -1 / r) taken off
    if A is not None and A.shape[1] > 1:
        from ._time import _within_fw

        x1f = _within_fw(_lagged(Yf, order, 1).reshape(n, r, d)[..., None], g, A)[..., 0].reshape(N, d)
        xLf = _within_fw(_lagged(Yf, order, CONTROL).reshape(n, r, d)[..., None], g, A)[..., 0].reshape(N, d)
        x1f[first], xLf[first] = 0.0, 0.0
        raw = _partial(e, x1f, xLf, v)
    else:
        raw = stat
    # a residual centred within its input is biased against its neighbour of the same input by
    # m = -1 / (r - 1) without memory (the deals' mean) and by m (1 + alpha) with it (Nickell's bias
    # of a within regression): raw = alpha + m (1 + alpha)
    scale = 1.0 + m if 1.0 + m > 0.5 else 1.0
    alpha, alpha_se = (raw - m) / scale, sd / scale
    row = row_of("memory", "lag", p, abs(z), alpha,
                 f"the shots of layer {layer} carry the shot acquired before them: {alpha:+.3g} of its value "
                 f"(+- {alpha_se:.2g}; beyond the shot {CONTROL} before, z = {z:.1f} over {null.size} deals of "
                 f"each input's shots to its times)")
    row["effect_se"] = float(alpha_se)
    return Lag(row, float(alpha), float(alpha_se), p, order)


def deals_p(null, stat: float, m: float, z: float) -> float:
    """Two-sided p of ``stat`` among the deals ``null`` (their mean ``m``): the share of deals at
    least as far from m, counting ``stat`` itself (exact under exchangeable shots); beyond every
    deal, the normal tail of ``z``, at most ``1 / (1 + B)``."""
    far = int(np.sum(np.abs(null - m) >= abs(stat - m)))
    if far:
        return float((1 + far) / (1 + null.size))
    return float(min(1.0 / (1 + null.size), 2.0 * stats.norm.sf(abs(z))))


def previous_means(Y, lag: Lag) -> np.ndarray:
    """(n, d): per input and neuron the mean of its shots' previous acquisitions' values -- how the
    shots' means move with alpha in :func:`undo` (minus this per unit of alpha)."""
    n, r, d = Y.shape
    return _lagged(np.asarray(Y, np.float64).reshape(n * r, d), lag.order, 1).reshape(n, r, d).mean(1)


def undo(Y, lag: Lag) -> np.ndarray:
    """The shots with the memory taken out: v_k = out_k - alpha out_{k-1} (exact for a memory of
    the ``memory`` effect's kind)."""
    n, r, d = Y.shape
    Yf = np.asarray(Y, np.float64).reshape(n * r, d)
    return (Yf - lag.alpha * _lagged(Yf, lag.order, 1)).reshape(n, r, d)

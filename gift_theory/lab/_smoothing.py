"""The activation smoothed by Gaussian noise: E sigma(z + sqrt(v) xi), its slope and variance.

The identification (:mod:`.identification`) reads every layer's mean map through this smoothing, so
its error is a bias of the model's mean at every cell. Six-point Gauss-Hermite in xi, enough at a
chip's usual levels (sd = sqrt(v) << 1: error below 1e-9 at sd 0.1), is far off once the noise
is as wide as the activation's bend: 4e-3 at sd = 1 and 0.08-0.23 at sd = 10 for tanh --
against the mean's standard error over a layer's cells, a false "activation_mismatch" on a
correctly specified file at s = 10. Here each cell takes the rule that is accurate at
its own sd:

* ``identity``: exact (z, 1, v);
* ``sin``: closed form (E sin(z + sd xi) = sin z exp(-v / 2), E sin^2 = (1 - cos 2z exp(-2v)) / 2);
* ``tanh`` (and ``sigmoid`` = (1 + tanh(u / 2)) / 2): Gauss-Hermite in xi where
  sd <= :data:`NARROW` (6 nodes up to sd 0.25, 16 beyond; error below 1e-7); beyond it, in u = z + sd xi over the activation's own
  scale: tanh u = sign u (1 - 2 q(|u|)), q(u) = 1 / (exp(2u) + 1), so
  E tanh U = erf(z / (sd sqrt 2)) - 2 int_0^inf q(u) (phi(u - z) - phi(u + z)) du and
  E tanh' U = int sech^2(u) phi(u - z) du, both smooth integrands on [0, U_MAX] resp.
  [-U_MAX, U_MAX] (q, sech^2 < 4e-10 beyond), by Gauss-Legendre; E tanh^2 U = 1 - E tanh' U.
  Error below 1e-7 at every sd above NARROW (tests/lab/test_identify.py checks it against
  adaptive quadrature).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import special

#: Gauss-Hermite rules by the cells' noise sd: 6 nodes up to sd 0.25 (error below 1e-7), 16 up to
#: :data:`NARROW` (below 3e-9); beyond it the cells are integrated over u
_GH = {n: (x, w / w.sum()) for n, (x, w) in ((n, np.polynomial.hermite_e.hermegauss(n)) for n in (6, 16))}
GH6_MAX = 0.25
NARROW = 0.5
#: q(u) and sech^2(u) are below 4e-10 beyond this
U_MAX = 11.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(96)


def _gauss_hermite(f, df, z, sd, var: bool, nodes: int = 6):
    m, g = np.zeros(np.shape(z)), np.zeros(np.shape(z))
    q = np.zeros(np.shape(z)) if var else None
    for x, w in zip(*_GH[nodes]):  # one node at a time, accumulated (2.6x faster than a node axis)
        F = f(z + sd * x)
        m += w * F
        g += w * df(F)
        if var:
            q += w * (F * F)
    return m, g, (np.maximum(q - m * m, 0.0) if var else None)


def _phi(u, sd):
    return np.exp(-0.5 * (u / sd) ** 2) / (sd * np.sqrt(2.0 * np.pi))


_U = 0.5 * U_MAX * (_GL_X + 1.0)  # [0, U_MAX]
_WU = 0.5 * U_MAX * _GL_W
_Q = _WU / (np.exp(2.0 * _U) + 1.0)
_SECH2 = _WU / np.cosh(_U) ** 2


#: cells per call of the compiled wide rule (the last chunk padded: one program for every size)
WIDE_CHUNK = 8192


def _x64():
    """The thread-local float64 context of the installed JAX (``jax.enable_x64``, before it
    ``jax.experimental.enable_x64``), or None."""
    import jax

    ctx = getattr(jax, "enable_x64", None)
    if ctx is None:
        try:
            from jax.experimental import enable_x64 as ctx
        except ImportError:
            return None
    return ctx


def _wide_rule():
    """The wide rule as a function of (z, sd) for JAX to compile, its nodes in float64."""
    import jax
    import jax.numpy as jnp

    with _x64()(True):
        U, Q, S2 = (jnp.asarray(v, jnp.float64) for v in (_U, _Q, _SECH2))

    def rule(z, sd):
        zc, sc = z[:, None], sd[:, None]
        c = 1.0 / (sc * np.sqrt(2.0 * np.pi))
        a = jnp.exp(-0.5 * ((U - zc) / sc) ** 2) * c
        b = jnp.exp(-0.5 * ((U + zc) / sc) ** 2) * c
        return jax.scipy.special.erf(z / (sd * np.sqrt(2.0))) - 2.0 * ((a - b) @ Q), (a + b) @ S2

    return rule


@functools.lru_cache(maxsize=1)
def _wide_program():
    """The wide rule compiled in float64 (XLA's exp is vectorised where numpy's float64 exp may
    not be: the (cells, nodes) Gaussian densities are most of a wide layer's identification),
    run-bound (:func:`gift_theory._xla.jit`: one program, run over every chunk of every map
    step), with XLA's own choices otherwise."""
    from .._xla import jit

    return jit(_wide_rule(), run_bound=True, cpu_options=False)


def _tanh_wide(z, sd):
    """(E tanh U, E tanh' U) for U ~ N(z, sd^2), sd > NARROW, over u (1-D arrays): both from the
    same two Gaussian densities at the nodes u >= 0 (sech^2 is even: its integral over
    [-U_MAX, U_MAX] folds onto [0, U_MAX]), in float64, chunked to bound the (cells, nodes)
    temporaries (:func:`_tanh_wide_numpy` is the same rule in numpy)."""
    x64 = _x64()
    if z.size < WIDE_CHUNK // 4 or x64 is None:  # a few cells: numpy's loop costs less than a padded chunk
        return _tanh_wide_numpy(z, sd)
    m, g = np.empty(z.shape), np.empty(z.shape)
    rule = _wide_program()
    with x64(True):  # thread-local: the caller's other JAX work keeps its dtypes
        for c0 in range(0, z.size, WIDE_CHUNK):
            zc, sc = z[c0:c0 + WIDE_CHUNK], sd[c0:c0 + WIDE_CHUNK]
            k = zc.size
            if k < WIDE_CHUNK:  # padded with a harmless cell (z = 0, sd = 1)
                zc = np.concatenate([zc, np.zeros(WIDE_CHUNK - k)])
                sc = np.concatenate([sc, np.ones(WIDE_CHUNK - k)])
            mc, gc = rule(zc, sc)
            m[c0:c0 + k], g[c0:c0 + k] = np.asarray(mc)[:k], np.asarray(gc)[:k]
    return m, g


def _tanh_wide_numpy(z, sd):
    """:func:`_tanh_wide` in numpy (the reference its compiled form is tested against)."""
    m, g = np.empty(z.shape), np.empty(z.shape)
    for c0 in range(0, z.size, WIDE_CHUNK):
        zc, sc = z[c0:c0 + WIDE_CHUNK, None], sd[c0:c0 + WIDE_CHUNK, None]
        a, b = _phi(_U - zc, sc), _phi(_U + zc, sc)
        m[c0:c0 + WIDE_CHUNK] = special.erf(zc[:, 0] / (sc[:, 0] * np.sqrt(2.0))) - 2.0 * ((a - b) @ _Q)
        g[c0:c0 + WIDE_CHUNK] = (a + b) @ _SECH2
    return m, g


def _tanh(z, sd, var: bool):
    df = lambda F: 1.0 - F * F  # noqa: E731
    m, g, q = _gauss_hermite(np.tanh, df, z, sd, var)
    mid = (sd > GH6_MAX) & (sd <= NARROW)
    if mid.any():
        mm, gm, qm = _gauss_hermite(np.tanh, df, z[mid], sd[mid], var, nodes=16)
        m[mid], g[mid] = mm, gm
        if var:
            q[mid] = qm
    wide = sd > NARROW
    if wide.any():
        mw, gw = _tanh_wide(z[wide], sd[wide])
        m[wide], g[wide] = mw, gw
        if var:
            q[wide] = np.maximum(1.0 - gw - mw * mw, 0.0)
    return m, g, q


def smoothed(activation: str, z, v, var: bool = True):
    """E sigma(z + sqrt(v) xi), its derivative in z and (``var``) Var sigma(z + sqrt(v) xi),
    xi ~ N(0, 1), elementwise over z and v (same shape), each accurate at its own noise sd (see
    the module docstring)."""
    z = np.asarray(z, np.float64)
    sd = np.sqrt(np.maximum(np.broadcast_to(np.asarray(v, np.float64), z.shape), 0.0))
    if activation == "identity":
        return z.copy(), np.ones_like(z), (sd * sd if var else None)
    if activation == "sin":
        damp = np.exp(-0.5 * sd * sd)
        m, g = np.sin(z) * damp, np.cos(z) * damp
        return m, g, (np.maximum(0.5 * (1.0 - np.cos(2.0 * z) * damp ** 4) - m * m, 0.0) if var else None)
    if activation == "sigmoid":  # (1 + tanh(u / 2)) / 2
        m, g, q = _tanh(0.5 * z.ravel(), 0.5 * sd.ravel(), var)
        return (0.5 * (1.0 + m)).reshape(z.shape), (0.25 * g).reshape(z.shape), (0.25 * q).reshape(z.shape) if var else None
    m, g, q = _tanh(z.ravel(), sd.ravel(), var)
    return m.reshape(z.shape), g.reshape(z.shape), (q.reshape(z.shape) if var else None)

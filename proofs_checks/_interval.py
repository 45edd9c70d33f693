"""Rigorous enclosures of a function of one variable over an interval, and its sup.

Theorem 1's condition (ass:Laplacian-properties) quantifies over every zeta between s0 and
st. A grid can miss the sup; here the sup of |h(zeta)| is bounded from above by interval
arithmetic with adaptive bisection (and from below by point values), so a decision taken
from it holds for every zeta.

Two evaluators of an enclosure ``[lo, hi] -> (L, U)`` with L <= h(zeta) <= U for all zeta:

* :func:`sympy_enclosure` -- a sympy expression, evaluated with ``mpmath.iv`` (directed
  rounding; transcendental functions without an ``iv`` version are taken at their
  endpoints where monotone);
* :func:`jaxpr_enclosure` -- a JAX function of a scalar (e.g. a pathwise derivative of a
  Monte-Carlo objective with fixed draws), traced once to a jaxpr and interpreted on
  float64 intervals: exact operations widen their result by one ulp outwards, library
  functions (tanh, exp, log, ...) by 4 ulp, sums and dot products by the classical
  bound gamma_n sum |a_i b_i| on the rounding error of any summation order. Quantities
  that do not depend on zeta are evaluated as plain float64 numbers (they define the
  function).
"""

from __future__ import annotations

import heapq
import math
from typing import Callable, NamedTuple

import numpy as np

_U = 2.0 ** -53          # unit roundoff of float64
_LIB_REL = 2.0 ** -46    # widening of library functions (tanh, exp, ...): 128 ulp, measured error <= 4 ulp


class IV:
    """An array of closed intervals [lo, hi] (float64; numpy or jax arrays)."""

    __slots__ = ("lo", "hi")

    def __init__(self, lo, hi=None):
        self.lo = lo
        self.hi = lo if hi is None else hi

    @property
    def shape(self):
        return self.lo.shape

    def __repr__(self):
        return f"IV({self.lo!r}, {self.hi!r})"


class _Lazy:
    """jax.numpy, imported on first use (keeps ``import proofs_checks`` light)."""

    def __getattr__(self, name):
        import jax.numpy
        return getattr(jax.numpy, name)


jnp = _Lazy()


def _down(x):
    return jnp.nextafter(x, -jnp.inf)


def _up(x):
    return jnp.nextafter(x, jnp.inf)


def _iv(x) -> IV:
    return x if isinstance(x, IV) else IV(jnp.asarray(x, jnp.float64))


def _hull(*arrays):
    st = jnp.stack(jnp.broadcast_arrays(*arrays))
    return st.min(0), st.max(0)


def _mag(a: IV):
    return jnp.maximum(jnp.abs(a.lo), jnp.abs(a.hi))


def _invalid(cond, lo, hi):
    """Where an operation is not defined on the interval, the enclosure is (-inf, inf)."""
    return IV(jnp.where(cond, -jnp.inf, lo), jnp.where(cond, jnp.inf, hi))


# --------------------------------------------------------------------------------------
# interval rules for the primitives that carry the variable
# --------------------------------------------------------------------------------------
def _add(a, b):
    a, b = _iv(a), _iv(b)
    return IV(_down(a.lo + b.lo), _up(a.hi + b.hi))


def _sub(a, b):
    a, b = _iv(a), _iv(b)
    return IV(_down(a.lo - b.hi), _up(a.hi - b.lo))


def _neg(a):
    return IV(-a.hi, -a.lo)


def _mul(a, b):
    if not isinstance(a, IV):
        a, b = b, a
    if not isinstance(b, IV):
        b = jnp.asarray(b, jnp.float64)
        p, q = a.lo * b, a.hi * b
        return IV(_down(jnp.minimum(p, q)), _up(jnp.maximum(p, q)))
    lo, hi = _hull(a.lo * b.lo, a.lo * b.hi, a.hi * b.lo, a.hi * b.hi)
    return IV(_down(lo), _up(hi))


def _div(a, b):
    a = _iv(a)
    if isinstance(b, IV):
        lo, hi = _hull(a.lo / b.lo, a.lo / b.hi, a.hi / b.lo, a.hi / b.hi)
        return _invalid((b.lo <= 0) & (b.hi >= 0), _down(lo), _up(hi))
    b = jnp.asarray(b, jnp.float64)
    p, q = a.lo / b, a.hi / b
    return IV(_down(jnp.minimum(p, q)), _up(jnp.maximum(p, q)))


def _integer_pow(a, y):
    if y < 0:
        return _div(jnp.ones_like(a.lo), _integer_pow(a, -y))
    if y == 0:
        return IV(jnp.ones_like(a.lo))
    plo, phi = a.lo ** y, a.hi ** y
    if y % 2:
        lo, hi = plo, phi                      # odd powers are increasing
    else:
        lo = jnp.where((a.lo <= 0) & (a.hi >= 0), 0.0, jnp.minimum(plo, phi))
        hi = jnp.maximum(plo, phi)
    rel = (y + 1) * 2 * _U                     # y - 1 rounded products
    return IV(lo - jnp.abs(lo) * rel - 1e-300, hi + jnp.abs(hi) * rel + 1e-300)


def _square(a):
    lo2, hi2 = a.lo * a.lo, a.hi * a.hi
    lo = jnp.where((a.lo <= 0) & (a.hi >= 0), 0.0, jnp.minimum(lo2, hi2))
    return IV(_down(lo), _up(jnp.maximum(lo2, hi2)))


def _widen_lib(lo, hi):
    return IV(lo - jnp.abs(lo) * _LIB_REL - 1e-300, hi + jnp.abs(hi) * _LIB_REL + 1e-300)


def _monotone(name, increasing=True):
    def rule(a):
        f = getattr(jnp, name)
        lo, hi = (f(a.lo), f(a.hi)) if increasing else (f(a.hi), f(a.lo))
        return _widen_lib(lo, hi)
    return rule


def _log(a):
    r = _widen_lib(jnp.log(a.lo), jnp.log(a.hi))
    return _invalid(a.lo <= 0, r.lo, r.hi)


def _sqrt(a):
    return _invalid(a.lo < 0, _down(jnp.sqrt(jnp.maximum(a.lo, 0.0))), _up(jnp.sqrt(jnp.maximum(a.hi, 0.0))))


def _rsqrt(a):
    return _div(1.0, _sqrt(a))


def _abs(a):
    lo = jnp.where((a.lo <= 0) & (a.hi >= 0), 0.0, jnp.minimum(jnp.abs(a.lo), jnp.abs(a.hi)))
    return IV(lo, _mag(a))


def _logistic(a):
    from jax.nn import sigmoid
    return _widen_lib(sigmoid(a.lo), sigmoid(a.hi))


def _erf(a):
    from jax.scipy.special import erf
    return _widen_lib(erf(a.lo), erf(a.hi))


def _trig(name, shift):
    """sin (shift 0) or cos (shift pi/2): endpoint values, widened to +-1 where an extremum
    (at pi/2 - shift + 2k pi for +1, -pi/2 - shift + 2k pi for -1) may lie inside."""
    def rule(a):
        f = getattr(jnp, name)
        flo, fhi = f(a.lo), f(a.hi)
        lo, hi = jnp.minimum(flo, fhi), jnp.maximum(flo, fhi)
        for target, val in ((jnp.pi / 2 - shift, 1.0), (-jnp.pi / 2 - shift, -1.0)):
            k = jnp.ceil((a.lo - target) / (2 * jnp.pi) - 1e-9)
            inside = target + 2 * jnp.pi * k <= a.hi + 1e-9 * (1 + jnp.abs(a.hi))
            lo, hi = (lo, jnp.where(inside, 1.0, hi)) if val > 0 else (jnp.where(inside, -1.0, lo), hi)
        w = _widen_lib(lo, hi)
        return IV(jnp.maximum(w.lo, -1.0), jnp.minimum(w.hi, 1.0))
    return rule


def _sum_error(n, mag_sum):
    """Rounding-error bound of a float64 sum of n terms of total magnitude mag_sum (any order)."""
    g = n * _U / (1 - n * _U)
    return g * mag_sum + 1e-300


def _dot_general(a, b, dimension_numbers):
    from jax import lax

    def dot(x, y):
        return lax.dot_general(x, y, dimension_numbers, precision=lax.Precision.HIGHEST,
                               preferred_element_type=jnp.float64)

    (ca, _), _ = dimension_numbers
    shape_a = a.shape if isinstance(a, IV) else jnp.shape(a)
    n = 1
    for i in ca:
        n *= int(shape_a[i])

    def mid_rad(x):
        if not isinstance(x, IV):
            x = jnp.asarray(x, jnp.float64)
            return x, jnp.zeros_like(x)
        m = 0.5 * (x.lo + x.hi)
        return m, _up(jnp.maximum(x.hi - m, m - x.lo))

    am, ar = mid_rad(a)
    bm, br = mid_rad(b)
    mid = dot(am, bm)
    absa, absb = jnp.abs(am), jnp.abs(bm)
    rad = dot(absa, br) + dot(ar, absb) + dot(ar, br)
    err = _sum_error(n + 2, dot(absa, absb) + rad)
    rad = _up(rad * (1 + 4 * (n + 2) * _U) + err)
    return IV(_down(mid - rad), _up(mid + rad))


def _reduce_sum(a, axes):
    ax = tuple(axes)
    n = 1
    for i in ax:
        n *= int(a.shape[i])
    err = _sum_error(n, _mag(a).sum(axis=ax))
    return IV(_down(a.lo.sum(axis=ax) - err), _up(a.hi.sum(axis=ax) + err))


_ELEMENTWISE = {
    "add": _add, "add_any": _add, "sub": _sub, "mul": _mul, "div": _div,
    "neg": _neg, "sqrt": _sqrt, "rsqrt": _rsqrt, "abs": _abs, "log": _log,
    "tanh": _monotone("tanh"), "exp": _monotone("exp"), "log1p": _monotone("log1p"),
    "expm1": _monotone("expm1"), "atan": _monotone("arctan"), "asinh": _monotone("arcsinh"),
    "sinh": _monotone("sinh"), "erf": _erf, "logistic": _logistic,
    "sin": _trig("sin", 0.0), "cos": _trig("cos", 3.141592653589793 / 2), "square": _square,
}

# primitives applied to lo and hi separately: rearrangements, or monotone non-decreasing in every input
_SEPARATE = {"broadcast_in_dim", "reshape", "transpose", "squeeze", "expand_dims", "slice", "rev", "copy",
             "copy_p", "reduce_max", "reduce_min", "max", "min", "concatenate", "pad", "dynamic_slice",
             "gather", "select_n", "split", "convert_element_type", "reduce_precision", "optimization_barrier",
             "stack", "unstack", "tile", "clamp"}
_CALLS = {"pjit", "closed_call", "core_call", "custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr",
          "remat", "checkpoint", "jit"}


def _separate(prim, ins, params):
    """Bind ``prim`` on the lower and on the upper ends; a select's predicate and an index
    must not depend on the variable."""
    name = prim.name
    if name == "clamp" and (isinstance(ins[0], IV) or isinstance(ins[2], IV)):
        raise ValueError("clamp bounds depend on the variable")
    if name == "select_n" and isinstance(ins[0], IV):
        raise ValueError("a branch (select) depends on the variable")
    if name in ("dynamic_slice", "gather") and any(isinstance(x, IV) for x in ins[1:]):
        raise ValueError("an index depends on the variable")
    if name == "convert_element_type" and str(params["new_dtype"]) != "float64":
        raise ValueError(f"conversion to {params['new_dtype']} inside the enclosure")

    def pick(x, end):
        return (x.lo if end == 0 else x.hi) if isinstance(x, IV) else x

    lo = prim.bind(*[pick(x, 0) for x in ins], **params)
    hi = prim.bind(*[pick(x, 1) for x in ins], **params)
    if prim.multiple_results:
        return [IV(l, h) for l, h in zip(lo, hi)]
    return IV(lo, hi)


def _inner_jaxpr(params):
    for k in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
        if k in params:
            j = params[k]
            return (j.jaxpr, j.consts) if hasattr(j, "consts") else (j, ())
    raise ValueError("call primitive without an inner jaxpr")


def eval_jaxpr_intervals(jaxpr, consts, *args):
    """Interpret ``jaxpr`` with some arguments given as :class:`IV` (the others concrete).
    Works under ``jax.jit`` (the interpretation is traced once)."""
    from jax.extend.core import Literal

    env = {}

    def read(v):
        return v.val if isinstance(v, Literal) else env[v]

    for v, c in zip(jaxpr.constvars, consts):
        env[v] = c
    for v, a in zip(jaxpr.invars, args):
        env[v] = a
    for eqn in jaxpr.eqns:
        ins = [read(v) for v in eqn.invars]
        prim, params = eqn.primitive, eqn.params
        name = prim.name
        if not any(isinstance(x, IV) for x in ins):
            out = prim.bind(*ins, **params)
            outs = list(out) if prim.multiple_results else [out]
        elif name in _CALLS:
            inner, inner_consts = _inner_jaxpr(params)
            outs = eval_jaxpr_intervals(inner, inner_consts, *ins)
        elif name in _ELEMENTWISE:
            outs = [_ELEMENTWISE[name](*ins)]
        elif name == "integer_pow":
            outs = [_integer_pow(ins[0], params["y"])]
        elif name == "dot_general":
            outs = [_dot_general(ins[0], ins[1], params["dimension_numbers"])]
        elif name == "reduce_sum":
            outs = [_reduce_sum(ins[0], params["axes"])]
        elif name in _SEPARATE:
            res = _separate(prim, ins, params)
            outs = res if isinstance(res, list) else [res]
        elif name == "stop_gradient":
            outs = ins
        else:
            raise ValueError(f"no interval rule for the primitive {name!r} on a quantity that depends on the variable")
        for v, o in zip(eqn.outvars, outs):
            env[v] = o
    return [read(v) for v in jaxpr.outvars]


def jaxpr_enclosure(fn: Callable, at: float):
    """An enclosure ``(lo, hi) -> IV`` (numpy arrays) of the JAX function ``fn`` of one float64
    scalar: traced once at ``at``, the interval interpretation compiled once with ``jax.jit``.
    Raises ValueError when an operation that depends on the variable has no interval rule."""
    import jax

    with jax.enable_x64(True):
        closed = jax.make_jaxpr(fn)(np.float64(at))

        def run(lo, hi):
            out = eval_jaxpr_intervals(closed.jaxpr, closed.consts, IV(lo, hi))
            if len(out) != 1:
                raise ValueError("the function must return one array")
            o = _iv(out[0])
            return o.lo, o.hi

        jax.eval_shape(run, np.float64(at), np.float64(at))     # rule errors surface here, once
        compiled = jax.jit(run)

    def enclose(lo: float, hi: float) -> IV:
        with jax.enable_x64(True):
            l, h = compiled(np.float64(lo), np.float64(hi))
            l, h = np.asarray(l), np.asarray(h)
        if np.any(np.isnan(l)) or np.any(np.isnan(h)):
            l, h = np.where(np.isnan(l), -np.inf, l), np.where(np.isnan(h), np.inf, h)
        return IV(l, h)

    return enclose


def box_enclosure(fn: Callable, *example, boxed=(0,)):
    """An enclosure of the JAX function ``fn(*args)`` whose arguments at the positions ``boxed``
    range over boxes: ``enclose(*args)`` takes an :class:`IV` (numpy ``lo``, ``hi`` of the
    argument's shape) at those positions and a concrete value elsewhere, and returns one
    :class:`IV` per output of ``fn`` (a tuple when ``fn`` returns a tuple, else one IV). Every
    value ``fn`` takes on the boxes lies in the returned intervals (float64 interval arithmetic,
    outward rounding; see the module docstring). Traced once at ``example``, compiled once.
    Raises ValueError when an operation on a boxed quantity has no interval rule."""
    import jax

    boxed = tuple(boxed)
    with jax.enable_x64(True):
        closed = jax.make_jaxpr(fn)(*example)
        tupled = isinstance(jax.eval_shape(fn, *example), tuple)

        def run(*flat):
            args, i = [], 0
            for k in range(len(example)):
                if k in boxed:
                    args.append(IV(flat[i], flat[i + 1]))
                    i += 2
                else:
                    args.append(flat[i])
                    i += 1
            outs = eval_jaxpr_intervals(closed.jaxpr, closed.consts, *args)
            return [(o.lo, o.hi) for o in map(_iv, outs)]

        def flat_of(args):
            out = []
            for k, a in enumerate(args):
                if k in boxed:
                    a = a if isinstance(a, IV) else IV(np.asarray(a, np.float64))
                    out += [np.asarray(a.lo, np.float64), np.asarray(a.hi, np.float64)]
                else:
                    out.append(a)
            return out

        jax.eval_shape(run, *flat_of(example))           # rule errors surface here, once
        compiled = jax.jit(run)

    def enclose(*args):
        with jax.enable_x64(True):
            res = compiled(*flat_of(args))
        outs = []
        for lo, hi in res:
            lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
            outs.append(IV(np.where(np.isnan(lo), -np.inf, lo), np.where(np.isnan(hi), np.inf, hi)))
        return tuple(outs) if tupled else outs[0]

    return enclose


# --------------------------------------------------------------------------------------
# interval arithmetic on numpy arrays (outward: every result is inflated by a bound on the
# float64 rounding of the midpoint-radius formulas)
# --------------------------------------------------------------------------------------
def iv_point(x) -> IV:
    """The degenerate interval [x, x]."""
    x = np.asarray(x, np.float64)
    return IV(x, x.copy())


def iv_mid_rad(a: IV):
    """(midpoint, radius) with [lo, hi] inside [mid - rad, mid + rad]."""
    lo, hi = np.asarray(a.lo, np.float64), np.asarray(a.hi, np.float64)
    mid = 0.5 * lo + 0.5 * hi
    rad = np.nextafter(np.maximum(hi - mid, mid - lo), np.inf)
    return mid, np.nextafter(rad * (1 + 4 * _U), np.inf)


def iv_mag(a: IV):
    """max |x| over the interval."""
    return np.maximum(np.abs(np.asarray(a.lo)), np.abs(np.asarray(a.hi)))


def iv_mig(a: IV):
    """min |x| over the interval (0 when it contains 0)."""
    lo, hi = np.asarray(a.lo), np.asarray(a.hi)
    return np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(np.abs(lo), np.abs(hi)))


def iv_dot(a: IV, b: IV) -> IV:
    """An enclosure of sum_i a_i b_i over the intervals (vectors of one length)."""
    am, ar = iv_mid_rad(a)
    bm, br = iv_mid_rad(b)
    n = am.size
    mid = float(am @ bm)
    rad = float(np.abs(am) @ br + ar @ np.abs(bm) + ar @ br)
    err = (n + 2) * _U / (1 - (n + 2) * _U) * (float(np.abs(am) @ np.abs(bm)) + rad) + 1e-300
    rad = float(np.nextafter(rad * (1 + 4 * (n + 2) * _U) + err, np.inf))
    return IV(np.nextafter(mid - rad, -np.inf), np.nextafter(mid + rad, np.inf))


def iv_sub(a: IV, b: IV) -> IV:
    return IV(np.nextafter(np.asarray(a.lo) - np.asarray(b.hi), -np.inf),
              np.nextafter(np.asarray(a.hi) - np.asarray(b.lo), np.inf))


class Krawczyk(NamedTuple):
    """The outcome of :func:`krawczyk`: ``unique_zero`` True when the box ``center +- radius``
    provably holds exactly one zero of the map, None when that was not shown (a degenerate zero,
    or no contraction)."""

    unique_zero: bool | None
    radius: np.ndarray
    contraction: float
    how: str


def krawczyk(center, value_at_center: IV, jacobian_mid, jacobian_on_box: Callable, *, tries: int = 6) -> Krawczyk:
    """Krawczyk's test for a zero of a map F: R^P -> R^P near ``center``.

    ``value_at_center`` encloses F(center) (rounding included), ``jacobian_mid`` is the float
    Jacobian at the center and ``jacobian_on_box(lo, hi)`` an :class:`IV` enclosure of the
    Jacobian over the box [lo, hi]. With C = jacobian_mid^-1 and X = center + [-r, r],
    K(X) = center - C F(center) + (I - C F'(X)) (X - center); if K(X) lies strictly inside X,
    F has exactly one zero in X (Krawczyk 1969; Moore, Kearfott, Cloud, *Introduction to
    Interval Analysis*, 2009, Thm 8.2). The magnitudes are bounded from above in float64 with a
    relative allowance for the rounding of the P-term products. r starts at twice |C F(center)|
    (plus a few ulp of the center) and is inflated up to ``tries`` times."""
    center = np.asarray(center, np.float64)
    P = center.size
    fm, fr = iv_mid_rad(value_at_center)
    A = np.asarray(jacobian_mid, np.float64)
    try:
        cond = float(np.linalg.cond(A))
        C = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        cond, C = math.inf, None
    if C is None or not np.all(np.isfinite(C)) or cond > 1e13:
        return Krawczyk(None, np.zeros(P), math.inf, f"Jacobian at the center singular or nearly so "
                        f"(condition number {cond:.3g}): a degenerate zero, not certified")
    slack = 1 + 8 * (P + 2) * _U
    absC = np.abs(C)
    cf = (np.abs(C @ fm) + absC @ fr) * slack                       # >= |C F(center)|
    r = 2 * cf + 4 * np.spacing(np.abs(center) + 1e-300) + 1e-300
    best = math.inf
    for _ in range(tries):
        Jb = jacobian_on_box(center - r, center + r)
        Jm, Jr = iv_mid_rad(Jb)
        M = np.abs(np.eye(P) - C @ Jm) * slack + absC @ Jr * slack + 4 * P * _U * (absC @ np.abs(Jm))
        k = (cf + M @ r) * slack
        ratio = float(np.max(k / r))
        best = min(best, ratio)
        if ratio < 1 and np.all(np.isfinite(k)):
            return Krawczyk(True, r, ratio, f"Krawczyk: K(X) inside X = center +- r (max r = {float(np.max(r)):.3g}, "
                            f"contraction {ratio:.3g} < 1; condition number of the Jacobian {cond:.3g}): exactly one "
                            f"zero in X")
        r = 2 * np.maximum(r, k)
    return Krawczyk(None, r, best, f"Krawczyk: no contraction (best ratio {best:.3g} after {tries} inflations; "
                    f"condition number {cond:.3g}): not certified")


# --------------------------------------------------------------------------------------
# sympy expressions with mpmath.iv
# --------------------------------------------------------------------------------------
def sympy_enclosure(expr, var, dps: int = 40):
    """An enclosure ``(lo, hi) -> (L, U)`` (mpmath interval arithmetic at ``dps`` digits,
    directed rounding; L, U returned as exact mpf numbers) of the sympy expression ``expr`` in
    the single symbol ``var``."""
    import mpmath
    import sympy as sp
    from mpmath import iv

    free = expr.free_symbols - {var}
    if free:
        raise ValueError(f"the expression depends on other symbols: {sorted(map(str, free))}")

    def ends(x):
        """The endpoints of an mpmath interval as exact mpf numbers."""
        return mpmath.mpf(x._mpi_[0]), mpmath.mpf(x._mpi_[1])

    def widen(lo, hi):
        """[lo, hi] widened by 10^-dps relatively (far beyond any rounding at dps + 10 digits)."""
        eps = mpmath.mpf(10) ** (-dps)
        return iv.mpf([lo - abs(lo) * eps - eps, hi + abs(hi) * eps + eps])

    def mono(f, increasing=True):
        def g(x):
            with mpmath.workdps(dps + 10):
                a, b = (f(t) for t in ends(x))
                lo, hi = (a, b) if increasing else (b, a)
                return widen(lo, hi)
        return g

    def cosh(x):  # even, minimum 1 at 0
        with mpmath.workdps(dps + 10):
            lo_, hi_ = ends(x)
            vals = (mpmath.cosh(lo_), mpmath.cosh(hi_))
            bottom = mpmath.mpf(1) if lo_ <= 0 <= hi_ else min(vals)
            return widen(bottom, max(vals))

    funcs = {sp.exp: iv.exp, sp.log: iv.log, sp.sin: iv.sin, sp.cos: iv.cos, sp.tan: iv.tan,
             sp.tanh: mono(mpmath.tanh), sp.sinh: mono(mpmath.sinh), sp.atan: mono(mpmath.atan),
             sp.asinh: mono(mpmath.asinh), sp.erf: mono(mpmath.erf), sp.cosh: cosh}

    def ev(e, x):
        if e == var:
            return x
        if e.is_Rational:
            return iv.mpf(int(e.p)) / iv.mpf(int(e.q))
        if e.is_Number or e.is_NumberSymbol:
            with mpmath.workdps(dps + 10):
                v = mpmath.mpf(str(sp.N(e, dps + 10)))
                return widen(v, v)
        if e.is_Add:
            out = iv.mpf(0)
            for a in e.args:
                out = out + ev(a, x)
            return out
        if e.is_Mul:
            out = iv.mpf(1)
            for a in e.args:
                out = out * ev(a, x)
            return out
        if e.is_Pow:
            base, ex = e.args
            if ex.is_Integer:
                b = ev(base, x)
                n = int(ex)
                if n >= 0:
                    return b ** n
                return iv.mpf(1) / (b ** (-n))
            if ex.is_Rational and ex.q == 2:
                return iv.sqrt(ev(base, x)) ** int(ex.p) if ex.p > 0 else iv.mpf(1) / iv.sqrt(ev(base, x)) ** int(-ex.p)
            return iv.exp(ev(ex, x) * iv.log(ev(base, x)))
        if isinstance(e, sp.Abs):
            a = ev(e.args[0], x)
            lo_, hi_ = ends(a)
            lo = 0 if lo_ <= 0 <= hi_ else min(abs(lo_), abs(hi_))
            return iv.mpf([lo, max(abs(lo_), abs(hi_))])
        f = funcs.get(e.func)
        if f is not None:
            return f(ev(e.args[0], x))
        raise ValueError(f"no interval rule for {e.func}")

    def enclose(lo: float, hi: float):
        old = iv.dps
        iv.dps = dps
        try:
            r = ev(expr, iv.mpf([float(lo), float(hi)]))
            with mpmath.workdps(dps + 10):
                return ends(r)
        finally:
            iv.dps = old

    return enclose


# --------------------------------------------------------------------------------------
# adaptive sup of |h| over [a, b]
# --------------------------------------------------------------------------------------
class SupBound(NamedTuple):
    """sup over [a, b] of a nonnegative function lies in [lower, upper] (``pieces`` intervals)."""

    lower: float
    upper: float
    argmax: float
    pieces: int


def sup_bound(upper_on: Callable[[float, float], float], lower_at: Callable[[float], float], a: float, b: float,
              *, rtol: float = 1e-3, max_pieces: int = 512, thresholds=(), fixed_lower: bool = False) -> SupBound:
    """Bracket sup_{[a, b]} F of a nonnegative function F by adaptive bisection.

    ``upper_on(lo, hi)`` bounds F from above on [lo, hi] (rigorously, e.g. from an interval
    enclosure). ``lower_at(z)`` returns a lower bound of F(z), or a pair (lower bound,
    reference value) when F carries statistical error (the reference -- e.g. the pointwise
    upper confidence limit -- is what the rigorous upper bound can at best reach). Bisects the
    piece with the largest upper bound until ``upper <= (1 + rtol) * max reference``, or every
    value in ``thresholds`` lies outside [lower, upper] (the decisions they stand for are
    settled), or ``max_pieces`` pieces. With ``fixed_lower`` only a, b and the midpoint give
    the lower bound (a confidence statement at points fixed in advance).
    """
    a, b = float(min(a, b)), float(max(a, b))

    def at(z):
        r = lower_at(z)
        return (r, r) if not isinstance(r, tuple) else r

    lower, ref, arg = 0.0, 0.0, a
    for z in (a, b, 0.5 * (a + b)):
        lo_z, ref_z = at(z)
        if lo_z > lower:
            lower, arg = lo_z, z
        ref = max(ref, ref_z)
    if a == b:
        return SupBound(lower, max(lower, upper_on(a, b)), a, 1)
    heap = [(-upper_on(a, b), a, b)]
    n = 1

    def settled(up):
        if up <= (1 + rtol) * ref:
            return True
        return bool(thresholds) and all(not (lower <= t <= up) for t in thresholds)

    while n < max_pieces and not settled(-heap[0][0]):
        _, lo, hi = heapq.heappop(heap)
        mid = 0.5 * (lo + hi)
        lo_z, ref_z = at(mid)
        ref = max(ref, ref_z)
        if not fixed_lower and lo_z > lower:
            lower, arg = lo_z, mid
        for p, q in ((lo, mid), (mid, hi)):
            heapq.heappush(heap, (-upper_on(p, q), p, q))
        n += 1
    return SupBound(lower, max(-heap[0][0], lower), arg, n)


def float_up(x) -> float:
    """The float nearest to the mpf ``x``, moved up if needed so that it is >= x."""
    import mpmath

    f = float(x)
    with mpmath.workdps(60):
        return f if mpmath.mpf(f) >= x else float(np.nextafter(f, np.inf))

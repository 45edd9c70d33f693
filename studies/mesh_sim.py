"""An independent MZI-mesh photonic chip: each layer's W realised as SVD + two Clements meshes + attenuators.

Plain numpy, written from the physics (no gift import). A layer's programmed weight matrix
W (shape (d_out, d_in)) is realised optically as

    W = U Sigma V^T                         (numpy's SVD; U (d_out, d_out), V^T (d_in, d_in))
    field in:  E_0 = a                       (the input amplitudes on d_in waveguides, coherent)
    E_1 = M_V E_0                            (a Clements mesh on d_in modes programmed to V^T)
    E_2 = P (sigma / sigma_max) E_1          (k = min(d_in, d_out) attenuators of transmission
                                              sigma_i / sigma_max <= 1; P drops the d_in - k
                                              unused modes or feeds vacuum into d_out - k new ones)
    E_3 = M_U E_2                            (a Clements mesh on d_out modes programmed to U)
    u   = sigma_max Re(E_3)                  (homodyne readout against a local oscillator of
                                              phase 0, then a fixed electronic gain sigma_max
                                              that undoes the attenuators' scaling)

so u = W_eff a with W_eff = sigma_max Re(M_U P diag(sigma / sigma_max) M_V) (the map is real
linear in the real input a). The network then follows reference §1-§2 exactly:

    a_0 = x + n_a0,   z_l = W_eff,l a_{l-1} + b_l + n_wl (+ readout noise),   a_l = tanh(z_l) + n_al,
    y = z_L,          n_* ~ N(0, s^2) independent.

**The Mach-Zehnder interferometer** (MZI) on modes (m, m+1): a phase shifter phi on the top
input arm, a 50:50 beamsplitter, a phase shifter theta on the top inner arm, a second
50:50 beamsplitter::

    T(theta, phi) = B(alpha_2) diag(e^{i theta}, 1) B(alpha_1) diag(e^{i phi}, 1),
    B(alpha) = [[cos(pi/4 + alpha), i sin(pi/4 + alpha)], [i sin(pi/4 + alpha), cos(pi/4 + alpha)]],

which for alpha = 0 is i e^{i theta/2} [[e^{i phi} sin(theta/2), cos(theta/2)],
[e^{i phi} cos(theta/2), -sin(theta/2)]] (:func:`mzi`).

**The decomposition** (Clements, Humphreys, Metcalf, Kolthammer, Walmsley, Optica 3, 1460
(2016)): an N x N unitary is brought to a diagonal D by alternately nulling the elements of
its lower-left triangle, diagonal by diagonal, with inverse MZIs from the right (odd
diagonals, nulling in the column) and MZIs from the left (even diagonals, nulling in the
row). Each left MZI is then moved through D (T^dagger D = D' T', a 2 x 2 identity solved
in :func:`_split_phases`), leaving U = D' (product of N(N-1)/2 MZIs) in a rectangular
layout of depth N (N - 1 for N = 2) and one output phase shifter per mode (D'). Programmed
phases are wrapped to [0, 2 pi) (a heater only adds phase). The MZIs are placed in columns
as early as their modes allow; the columns are the layout's vertical slices.

**Imperfections** (:class:`Imperfections`, each off by default and switchable per layer):

``bs_error``      the standard deviation (rad) of each beamsplitter's splitting-angle error
                  alpha (two per MZI), fixed per device: the 50:50 splitters are off.
``phase_error``   the standard deviation (rad) of a fixed error on every phase shifter
                  (theta, phi and the output phases), fixed per device (calibration error).
``jitter``        the standard deviation (rad) of a fresh error on every phase shifter in
                  every shot (heater/laser phase noise): W_eff differs from shot to shot.
``crosstalk``     kappa: each heater's phase is its programmed phase plus kappa times the sum
                  of its neighbours' programmed phases. Neighbours: the heaters of the same
                  kind (theta or phi) in the same column on the adjacent MZIs (top modes
                  m - 2 and m + 2), and the output phase shifters of the adjacent modes.
``loss_db``       uniform insertion loss, dB of optical power per MZI column. The mesh is loss
                  balanced: every mode crosses every column (an idle edge waveguide loses as
                  much as an MZI, as with dummy MZIs), so the field on every mode is scaled by
                  10^(-loss_db depth / 20) and W_eff = g W exactly, g = 10^(-loss_db (depth_V
                  + depth_U) / 20). The electronic gain is fixed to sigma_max (it undoes the
                  attenuators, not the loss: the programmer does not know the loss).
``readout_noise`` the standard deviation of an extra additive homodyne-detection noise on
                  every weighted sum u (LO-dominated shot noise and electronics), per shot.

``layers`` maps an imperfection's name to the 1-based layers it acts on (absent: all).
With every imperfection off the realised W equals the programmed W to rounding
(``tests/studies/test_mesh_sim.py``: 1e-10 on random shapes).

**Labels** (reference §6 classes; ``MESH_PHYSICS``; the reasons):

- uniform loss -> ``gain_error`` in the layers it acts on: W_eff = g W exactly (one fixed
  gain per layer, the class's definition and the built-in ``layer_gain``'s model).
- splitting-ratio errors, fixed phase errors, heater crosstalk -> ``weight_error`` in the
  layers they act on: a fixed linear map other than a gain. A small error on a mesh
  element gives W_eff - W = A W + W B (A from the errors in M_U, B from those in M_V), not a
  multiple of W, so gain_error is not acceptable; nor are they iid N(0, e^2) offsets, so
  the catalogue's ``weight_error`` contains them (its free per-device offsets can take any
  W_eff) without being their model (``contained_in``).
- per-shot phase jitter -> ``input_dependent_noise`` in every layer it acts on: the per-shot
  error dW a has a variance that grows with the input's energy |a_{l-1}|^2 (zero for a
  zero input), a signal-dependent noise. ``correlated_noise`` is also accepted as the first
  class: the errors of the shared mesh elements reach every output through U, so the noise
  of one shot is shared by the layer's neurons: every pair of neurons is correlated (on the
  study's 16-32-16-8 chip the mean |correlation| of the jitter noise between two neurons
  of layer 2 is about 0.1, against 0 for independent noise; ``tests/studies/
  test_mesh_sim.py`` checks that it is far from 0), which is the symptom correlated_noise
  names (noise shared by the neurons of a layer within a shot), so a diagnosis naming it
  sends the user to a shared fluctuating source, the right place. It is not additive (it
  vanishes with the input), so input_dependent_noise is the primary class.
  gain_fluctuation is not accepted: the noise is not proportional to each neuron's own
  signal u_i (a gain's noise is u u^T-shaped; jitter's is not).
- null (no imperfection) -> nothing detected.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

TWO_PI = 2.0 * np.pi


# ---------------------------------------------------------------------------------- one MZI

def beamsplitter(alpha=0.0):
    """B(alpha): (..., 2, 2), a lossless beamsplitter of splitting angle pi/4 + alpha (0: 50:50)."""
    a = np.pi / 4 + np.asarray(alpha, dtype=np.float64)
    c, s = np.cos(a), np.sin(a)
    return np.stack([np.stack([c, 1j * s], -1), np.stack([1j * s, c], -1)], -2)


def mzi(theta, phi, alpha1=0.0, alpha2=0.0):
    """T(theta, phi) = B(alpha2) diag(e^{i theta}, 1) B(alpha1) diag(e^{i phi}, 1): (..., 2, 2)."""
    theta, phi = np.asarray(theta, np.float64), np.asarray(phi, np.float64)
    one = np.ones_like(theta + phi)
    P = lambda x: np.stack([np.stack([np.exp(1j * x) * one, 0 * one], -1), np.stack([0 * one, one], -1)], -2)  # noqa: E731
    return beamsplitter(alpha2) @ P(theta) @ beamsplitter(alpha1) @ P(phi)


def _null_from_left(u, v):
    """(theta, phi) with (T [u, v]^T)[1] = 0: e^{i phi} cos(theta/2) u = sin(theta/2) v."""
    return 2.0 * np.arctan2(abs(u), abs(v)), np.angle(v) - np.angle(u)


def _null_from_right(u, v):
    """(theta, phi) with ([u, v] T^dagger)[0] = 0: e^{-i phi} sin(theta/2) u = -cos(theta/2) v."""
    return 2.0 * np.arctan2(abs(v), abs(u)), np.angle(u) - np.angle(v) - np.pi


def _split_phases(B):
    """A 2 x 2 unitary B as diag(e^{i psi1}, e^{i psi2}) T(theta, phi): returns (psi1, psi2, theta, phi).

    With g = i e^{i theta/2}: B00 = e^{i(psi1+phi)} g s, B01 = e^{i psi1} g c, B10 = e^{i(psi2+phi)} g c,
    B11 = -e^{i psi2} g s (s, c = sin, cos of theta/2). The phases are read from the two larger
    elements so the result is exact to rounding whatever theta is.
    """
    theta = 2.0 * np.arctan2(abs(B[0, 0]), abs(B[0, 1]))
    ag = np.pi / 2 + theta / 2
    if abs(B[0, 1]) >= abs(B[0, 0]):
        psi1 = np.angle(B[0, 1]) - ag
        phi = np.angle(B[0, 0]) - ag - psi1
        psi2 = np.angle(B[1, 0]) - ag - phi
    else:
        psi2 = np.angle(-B[1, 1]) - ag
        phi = np.angle(B[1, 0]) - ag - psi2
        psi1 = np.angle(B[0, 0]) - ag - phi
    return psi1, psi2, theta, phi


# ---------------------------------------------------------------------------------- the mesh

@dataclass(frozen=True)
class Mesh:
    """A programmed rectangular (Clements) mesh on ``n`` modes, MZIs in the order light meets them.

    n : modes
    top : (k,) int, the top mode m of each MZI (it acts on modes m, m + 1); k = n (n - 1) / 2
    column : (k,) int, the MZI's column (0 .. depth - 1)
    theta, phi : (k,) programmed phases in [0, 2 pi)
    out_phase : (n,) the output phase shifters' programmed phases in [0, 2 pi)
    depth : the number of columns
    """

    n: int
    top: np.ndarray
    column: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    out_phase: np.ndarray
    depth: int

    def neighbours(self):
        """(k, 2) int: the MZIs of the same column with top mode m - 2 and m + 2 (-1: none)."""
        where = {(int(c), int(m)): i for i, (c, m) in enumerate(zip(self.column, self.top))}
        return np.array([[where.get((int(c), int(m) - 2), -1), where.get((int(c), int(m) + 2), -1)]
                         for c, m in zip(self.column, self.top)], dtype=int).reshape(-1, 2)


def clements(U) -> Mesh:
    """The Clements et al. (2016) decomposition of an (N, N) unitary into a programmed :class:`Mesh`."""
    U = np.array(U, dtype=np.complex128)
    N = U.shape[0]
    if U.shape != (N, N) or not np.allclose(U.conj().T @ U, np.eye(N), atol=1e-9):
        raise ValueError(f"clements: a unitary (N, N) matrix is needed, got shape {U.shape}")
    right, left = [], []                      # (top mode, theta, phi) in the order applied
    for i in range(1, N):
        if i % 2 == 1:
            for j in range(i):                # null U[N-1-j, i-1-j] with T^dagger from the right on columns (c, c+1)
                r, c = N - 1 - j, i - 1 - j
                th, ph = _null_from_right(U[r, c], U[r, c + 1])
                T = mzi(th, ph)
                U[:, c:c + 2] = U[:, c:c + 2] @ T.conj().T
                right.append((c, th, ph))
        else:
            for j in range(1, i + 1):         # null U[N+j-i-1, j-1] with T from the left on rows (r-1, r)
                r, c = N + j - i - 1, j - 1
                th, ph = _null_from_left(U[r - 1, c], U[r, c])
                T = mzi(th, ph)
                U[r - 1:r + 1, :] = T @ U[r - 1:r + 1, :]
                left.append((r - 1, th, ph))
    D = np.diag(U).copy()                     # U is now diagonal (unit-modulus entries)
    moved = []
    for m, th, ph in reversed(left):          # T^dagger D = D' T'
        B = mzi(th, ph).conj().T @ np.diag(D[m:m + 2])
        psi1, psi2, th2, ph2 = _split_phases(B)
        D[m], D[m + 1] = np.exp(1j * psi1), np.exp(1j * psi2)
        moved.append((m, th2, ph2))
    # light meets the right-MZIs in the order found, then the moved left-MZIs from the last found to the first
    order = right + moved
    top = np.array([o[0] for o in order], dtype=int)
    column, free = np.zeros(len(order), dtype=int), np.zeros(N, dtype=int)
    for i, m in enumerate(top):               # as early as the MZI's two modes allow
        column[i] = max(free[m], free[m + 1])
        free[m] = free[m + 1] = column[i] + 1
    return Mesh(n=N, top=top, column=column,
                theta=np.mod(np.array([o[1] for o in order], dtype=np.float64), TWO_PI),
                phi=np.mod(np.array([o[2] for o in order], dtype=np.float64), TWO_PI),
                out_phase=np.mod(np.angle(D), TWO_PI), depth=int(free.max(initial=0)))


def propagate(E, mesh: Mesh, theta=None, phi=None, out_phase=None, alpha=None, field_loss=1.0):
    """The field after the mesh: E (..., n) complex in, (..., n) out.

    theta, phi : (..., k) or (k,) the phases actually applied (default: the programmed ones);
        a leading batch shape gives each field its own phases (per-shot jitter)
    out_phase : (..., n) or (n,)
    alpha : (k, 2) the beamsplitters' splitting-angle errors (default 0)
    field_loss : the field transmission of one column, applied to every mode of every column
    """
    E = np.array(E, dtype=np.complex128)
    theta = mesh.theta if theta is None else theta
    phi = mesh.phi if phi is None else phi
    out_phase = mesh.out_phase if out_phase is None else out_phase
    alpha = np.zeros((len(mesh.top), 2)) if alpha is None else alpha
    for c in range(mesh.depth):
        idx = np.flatnonzero(mesh.column == c)
        m = mesh.top[idx]
        top, bot = E[..., m] * np.exp(1j * np.asarray(phi)[..., idx]), E[..., m + 1]
        c1, s1 = np.cos(np.pi / 4 + alpha[idx, 0]), np.sin(np.pi / 4 + alpha[idx, 0])
        top, bot = c1 * top + 1j * s1 * bot, 1j * s1 * top + c1 * bot
        top = top * np.exp(1j * np.asarray(theta)[..., idx])
        c2, s2 = np.cos(np.pi / 4 + alpha[idx, 1]), np.sin(np.pi / 4 + alpha[idx, 1])
        E[..., m], E[..., m + 1] = c2 * top + 1j * s2 * bot, 1j * s2 * top + c2 * bot
        if field_loss != 1.0:
            E = E * field_loss
    return E * np.exp(1j * np.asarray(out_phase))


def mesh_matrix(mesh: Mesh, **kw):
    """The (n, n) transfer matrix of the mesh (columns: the response to each input mode)."""
    return propagate(np.eye(mesh.n), mesh, **kw).T


# ---------------------------------------------------------------------------------- a layer and the chip

@dataclass(frozen=True)
class OpticalLayer:
    """One programmed layer: W = U diag(sigma) V^T realised as M_U P diag(sigma / gain) M_V, times ``gain``.

    W : (d_out, d_in) the programmed weights; V : Mesh on d_in modes (programmed to V^T);
    U : Mesh on d_out modes; sigma : (k,) singular values, k = min(d_in, d_out);
    gain : sigma_max (the electronic gain; 1 for W = 0)
    """

    W: np.ndarray
    V: Mesh
    U: Mesh
    sigma: np.ndarray
    gain: float


def program_layer(W) -> OpticalLayer:
    """The phases and attenuations that realise W (shape (d_out, d_in)) on an ideal chip."""
    W = np.asarray(W, dtype=np.float64)
    Uo, S, Vt = np.linalg.svd(W)
    gain = float(S.max()) if S.size and S.max() > 0 else 1.0
    return OpticalLayer(W=W, V=clements(Vt), U=clements(Uo), sigma=S, gain=gain)


@dataclass(frozen=True)
class Imperfections:
    """The chip's imperfections (all off by default; see the module docstring for each one's physics)."""

    bs_error: float = 0.0
    phase_error: float = 0.0
    jitter: float = 0.0
    crosstalk: float = 0.0
    loss_db: float = 0.0
    readout_noise: float = 0.0
    layers: dict = field(default_factory=dict)

    def on(self, name: str, layer: int) -> float:
        """The strength of ``name`` in 1-based ``layer`` (0 where it does not act)."""
        value = getattr(self, name)
        return value if name not in self.layers or layer in self.layers[name] else 0.0


@dataclass(frozen=True)
class MeshErrors:
    """A mesh's fixed device draws: alpha (k, 2) splitting-angle errors, d_theta, d_phi (k,), d_out (n,)."""

    alpha: np.ndarray
    d_theta: np.ndarray
    d_phi: np.ndarray
    d_out: np.ndarray


def _device_errors(rng, mesh: Mesh, bs_error: float, phase_error: float) -> MeshErrors:
    """Draw a mesh's fixed errors; nothing is drawn for an imperfection that is off."""
    k = len(mesh.top)
    alpha = rng.normal(0.0, bs_error, (k, 2)) if bs_error else np.zeros((k, 2))
    if phase_error:
        d_theta, d_phi, d_out = rng.normal(0.0, phase_error, k), rng.normal(0.0, phase_error, k), \
            rng.normal(0.0, phase_error, mesh.n)
    else:
        d_theta, d_phi, d_out = np.zeros(k), np.zeros(k), np.zeros(mesh.n)
    return MeshErrors(alpha, d_theta, d_phi, d_out)


def heater_phases(mesh: Mesh, kappa: float):
    """(theta, phi, out_phase) after thermal crosstalk: each phase + kappa (sum of its neighbours' programmed phases)."""
    if not kappa:
        return mesh.theta, mesh.phi, mesh.out_phase
    nb = mesh.neighbours()
    pad = lambda p: np.append(p, 0.0)  # noqa: E731  (index -1 reads the appended 0: no neighbour)
    th = mesh.theta + kappa * (pad(mesh.theta)[nb[:, 0]] + pad(mesh.theta)[nb[:, 1]])
    ph = mesh.phi + kappa * (pad(mesh.phi)[nb[:, 0]] + pad(mesh.phi)[nb[:, 1]])
    o = mesh.out_phase
    out = o + kappa * (np.concatenate([[0.0], o[:-1]]) + np.concatenate([o[1:], [0.0]]))
    return th, ph, out


@dataclass(frozen=True)
class DeviceLayer:
    """A programmed layer on one device: its meshes' fixed errors and the chip's imperfections there."""

    layer: OpticalLayer
    errV: MeshErrors
    errU: MeshErrors
    kappa: float
    loss_db: float
    jitter: float

    def _phases(self, mesh, err):
        th, ph, out = heater_phases(mesh, self.kappa)
        return th + err.d_theta, ph + err.d_phi, out + err.d_out

    def field_loss(self):
        return 10.0 ** (-self.loss_db / 20.0)

    def apply(self, a, rng=None, average=False):
        """u = gain Re(M_U P diag(sigma / gain) M_V a): a (..., d_in) real -> (..., d_out).

        With ``jitter`` a fresh phase error on every phase shifter for each leading index of a
        (one shot each), drawn from ``rng``; otherwise the fixed map (:meth:`matrix`).
        ``average``: the mean over the jitter instead, exactly: every phase factor appears once
        in the product and the errors are independent, so each e^{i(p + eps)} is replaced by its
        mean e^{i p} e^{-jitter^2 / 2} (a complex phase p + i jitter^2 / 2).
        """
        L = self.layer
        d_out, d_in = L.W.shape
        k = L.sigma.size
        t = self.field_loss()
        shape = a.shape[:-1]
        E = np.asarray(a, dtype=np.float64).reshape(-1, d_in).astype(np.complex128)
        outs = []
        for mesh, err in ((L.V, self.errV), (L.U, self.errU)):
            th, ph, out = self._phases(mesh, err)
            if self.jitter and average:
                damp = 0.5j * self.jitter ** 2
                th, ph, out = th + damp, ph + damp, out + damp
            elif self.jitter:
                B = E.shape[0]
                th = th + rng.normal(0.0, self.jitter, (B, th.size))
                ph = ph + rng.normal(0.0, self.jitter, (B, ph.size))
                out = out + rng.normal(0.0, self.jitter, (B, out.size))
            outs.append((mesh, th, ph, out, err.alpha))
        mesh, th, ph, out, alpha = outs[0]
        E = propagate(E, mesh, th, ph, out, alpha, t)
        mid = np.zeros((E.shape[0], d_out), dtype=np.complex128)
        mid[:, :k] = E[:, :k] * (L.sigma / L.gain)          # attenuators; vacuum on the other modes
        mesh, th, ph, out, alpha = outs[1]
        E = propagate(mid, mesh, th, ph, out, alpha, t)
        return (L.gain * E.real).reshape(shape + (d_out,))

    def matrix(self):
        """The realised fixed W_eff (d_out, d_in) (without jitter)."""
        return replace(self, jitter=0.0).apply(np.eye(self.layer.W.shape[1])).T

    def mean_matrix(self):
        """E[W_eff] (d_out, d_in) over the per-shot jitter (:meth:`apply` with ``average``)."""
        return self.apply(np.eye(self.layer.W.shape[1]), average=True).T


def build_device(rng, Ws, imperfections: Imperfections) -> list[DeviceLayer]:
    """Program every layer and draw the device's fixed errors (in layer order, V's then U's)."""
    out = []
    for l, W in enumerate(Ws, start=1):
        L = program_layer(W)
        errV = _device_errors(rng, L.V, imperfections.on("bs_error", l), imperfections.on("phase_error", l))
        errU = _device_errors(rng, L.U, imperfections.on("bs_error", l), imperfections.on("phase_error", l))
        out.append(DeviceLayer(L, errV, errU, imperfections.on("crosstalk", l), imperfections.on("loss_db", l),
                               imperfections.on("jitter", l)))
    return out


def uniform_loss_gain(W_shape, loss_db: float) -> float:
    """g of a uniform loss on a layer of shape (d_out, d_in): 10^(-loss_db (depth_V + depth_U) / 20)."""
    d_out, d_in = W_shape
    depth = lambda n: 0 if n < 2 else (1 if n == 2 else n)  # noqa: E731  (the rectangular layout's columns)
    return float(10.0 ** (-loss_db * (depth(d_in) + depth(d_out)) / 20.0))


def simulate_mesh(rng, Ws, bs, x, r, s, imperfections: Imperfections = Imperfections(), t=None, chunk=4096,
                  device=None):
    """The chip: reference §1-§2 with each weighted sum realised by the mesh.

    Parameters
    ----------
    rng : numpy Generator (device draws first, then per-shot draws layer by layer)
    Ws, bs : programmed weights, W_l (d_l, d_{l-1}), b_l (d_l,)
    x : (n, d_0) inputs; r : shots per input; s : the additive noise level
    imperfections : :class:`Imperfections`
    t : None (a uniformly random acquisition order, drawn here) or (n, r) times in [0, 1]
    chunk : shots per batch of the per-shot (jitter) propagation
    device : the output of :func:`build_device` (default: built here from ``rng``)

    Returns
    -------
    y : (n, r, d_L); taps : [a_1 .. a_{L-1}], each (n, r, d_l); t : (n, r);
    W_eff : [realised fixed W_eff,l] (without jitter)
    """
    n = x.shape[0]
    dev = build_device(rng, Ws, imperfections) if device is None else device
    if t is None:
        order = rng.permutation(n * r)
        t = (np.argsort(order).reshape(n, r) / max(n * r - 1, 1)).astype(np.float64)
    Weffs = [d.matrix() for d in dev]
    a = x[:, None, :] + rng.normal(0.0, s, (n, r, x.shape[1]))
    taps = []
    for l, (d, b) in enumerate(zip(dev, bs), start=1):
        if d.jitter:
            flat = a.reshape(n * r, -1)
            u = np.concatenate([d.apply(flat[i:i + chunk], rng) for i in range(0, n * r, chunk)]).reshape(n, r, -1)
        else:
            u = a @ Weffs[l - 1].T
        z = u + b + rng.normal(0.0, s, u.shape)
        ro = imperfections.on("readout_noise", l)
        if ro:
            z = z + rng.normal(0.0, ro, u.shape)
        if l < len(dev):
            a = np.tanh(z) + rng.normal(0.0, s, u.shape)
            taps.append(a)
        else:
            a = z
    return a, taps, t, Weffs


# ---------------------------------------------------------------------------------- the study's physics

@dataclass(frozen=True)
class MeshPhysics:
    """One physics of the mesh study with what a correct diagnosis should say.

    name : the file name's stem; mechanism : its primary reference §6 class; accepted : the
    classes accepted as the first mechanism (the primary one included); layers(L) : where the
    one-step check must fail; expressible_by / contained_in : as in studies.contract_sim;
    imperfections(L, strength) : the :class:`Imperfections` of a file; definition : one line.
    """

    name: str
    mechanism: str
    accepted: tuple
    scope: str
    expressible_by: tuple
    contained_in: tuple
    definition: str
    strengths: dict

    def layers(self, L: int) -> list[int]:
        if self.scope == "none":
            return []
        if self.scope == "layer2":
            return [min(2, L)]
        return list(range(1, L + 1))

    def imperfections(self, L: int, strength: str) -> Imperfections:
        kw = dict(self.strengths[strength])
        if self.scope == "layer2":
            kw["layers"] = {k: (min(2, L),) for k in kw}
        return Imperfections(**kw)


#: the study's physics and strengths. "small": the loop should fit them; "large": 0.2 dB per
#: MZI column, crosstalk that scrambles W, errors as large as W (issue 24)
MESH_PHYSICS = {p.name: p for p in (
    MeshPhysics("mesh_bs_ratio", "weight_error", ("weight_error",), "all", (), ("weight_error",),
                "every beamsplitter's splitting angle pi/4 + alpha, alpha ~ N(0, sd^2) fixed per device",
                {"small": {"bs_error": 0.02}, "large": {"bs_error": 0.08}}),
    MeshPhysics("mesh_phase_error", "weight_error", ("weight_error",), "layer2", (), ("weight_error",),
                "layer 2 only: every phase shifter off by N(0, sd^2), fixed per device",
                {"small": {"phase_error": 0.01}, "large": {"phase_error": 0.1}}),
    MeshPhysics("mesh_phase_jitter", "input_dependent_noise", ("input_dependent_noise", "correlated_noise"), "all",
                (), (), "every phase shifter off by a fresh N(0, sd^2) in every shot",
                {"small": {"jitter": 0.01}, "large": {"jitter": 0.03}}),
    MeshPhysics("mesh_crosstalk", "weight_error", ("weight_error",), "all", (), ("weight_error",),
                "each heater's phase + kappa (sum of its neighbours' programmed phases)",
                {"small": {"crosstalk": 0.002}, "large": {"crosstalk": 0.05}}),
    MeshPhysics("mesh_loss", "gain_error", ("gain_error",), "all", ("layer_gain",), ("weight_error",),
                "uniform insertion loss per MZI column: W_eff = g W, g = 10^(-dB depth / 20)",
                {"small": {"loss_db": 0.02}, "large": {"loss_db": 0.2}}),
    MeshPhysics("none", None, (), "none", (), (), "no imperfection (the contract's awgn only)",
                {"small": {}, "large": {}}),
)}

#: the study's default strengths (issue 24's set: the weight errors small, loss and crosstalk large)
DEFAULT_STRENGTH = {"mesh_bs_ratio": "small", "mesh_phase_error": "small", "mesh_phase_jitter": "small",
                    "mesh_crosstalk": "large", "mesh_loss": "large", "none": "small"}

#: the setting of the mesh study: the issue's 16-32-16-8 chip, 240 inputs x 64 shots, s = 0.05
MESH_SETTING = {"widths": (16, 32, 16, 8), "n": 240, "r": 64, "s": 0.05}

"""A numeric family: the 3-4-2 tanh ONN of `gift check` (teacher data, n = 1024 points as the
data measure mu), per-input losses averaged over K2 = 16 fixed sign-symmetric noise draws
(pathwise in s: the forward pass scales standard draws by s); the objective is the mean of those
per-input values. w0 is a critical point of it at s0 = 0.1 (trained, then solved by Newton's
method). wt is the trivial point (W = 0, hidden b = 0, b_L = mean y), a degenerate critical point
for every s, which `certify` proves exactly (by the draws' sign symmetry). Use with --s0 0.1."""

from proofs_checks._onn import onn_family

J, w0, wt, _problem, _w0, _wt, certify = onn_family()

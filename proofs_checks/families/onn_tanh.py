"""A numeric family: the 3-4-2 tanh ONN of `gift check` (teacher data, n = 1024 points as the
data measure mu), w0 trained at s0 = 0.1, per-input losses averaged over K2 = 16 fixed noise
draws (pathwise in s: the forward pass scales standard draws by s). wt is the trivial critical
point of J_s for every s (W = 0, hidden b = 0, b_L = mean y). Use with --s0 0.1."""

from proofs_checks._onn import onn_family

J, w0, wt, *_ = onn_family()

"""python channel_values_dump.py OUT.npz: channel_values of t240 and big.npz for two models at block sizes of
16 MiB and 2 MiB (run at two commits, then compare the arrays)."""
import sys, jax, numpy as np, gift_theory.lab as lab
from gift_theory.lab import _shots as S, _channels as Ch
from gift_theory import Physics
res = {}
for f in ["/tmp/t240.npz", "big.npz"]:
    meas = lab.load_measurement(f)
    ref = Ch.reference(jax.random.key(0), meas)
    for spec in (["awgn=0.05"], ["awgn=0.05", "shot=0.01", "laplace"]):
        model = S.Model(Physics.parse(spec))
        for nbytes in (16 << 20, 2 << 20):
            S.SHOT_BLOCK_BYTES = nbytes
            res[(f, tuple(spec), nbytes)] = Ch.channel_values(jax.random.key(9), model, meas, ref)
np.savez(sys.argv[1], **{str(i): v for i, v in enumerate(res.values())})
print(list(res))

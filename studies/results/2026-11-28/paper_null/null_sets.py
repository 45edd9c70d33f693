"""The awgn model's test on null measurements at the paper's scale (section 4 of ../README.md).

    python null_sets.py S0 ST SEED ARCH SETS INPUTS SHOTS > rows.jsonl

The trained w0 of ``load_setting("mnist5k", ARCH, S0, SEED)`` (cached, or trained with the
sweeps' recipe), the first INPUTS training images, a simulated chip whose only physics is
awgn at the level the sweeps use for ST (``paper_figures._jobs.true_noise``), SHOTS shots with
taps; data set k is drawn with key 100 + k and the lab's session with key 7 + k. Each row:
the baseline's fitted s, its held-out p-value, Q, its null sd, the floor and Q per layer.
"""
import json
import sys
import time

import jax

from gift_theory.chips import simulate_measurement
from gift_theory.effects import Physics
from gift_theory.finetune._run import load_setting
from gift_theory.lab._diagnose import Session
from paper_figures._jobs import true_noise

s0, st, seed, arch, N, n, shots = (float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), sys.argv[4],
                                   int(sys.argv[5]), int(sys.argv[6]), int(sys.argv[7]))
s_true, _ = true_noise("awgn", st)
ds, arch_, w0 = load_setting("mnist5k", arch, s0, seed)
phys = Physics.create(s=s_true)
for k in range(N):
    t = time.time()
    meas = simulate_measurement(jax.random.PRNGKey(100 + k), w0, ds.x_train[:n], phys, shots=shots,
                                activation=arch_.activation, taps=True)
    ses = Session(jax.random.PRNGKey(7 + k), meas)
    c = ses.baseline_comparison
    print(json.dumps({"set": k, "s_true": s_true, "s": float(ses.baseline.physics.s), "p": c.p_value,
                      "Q": c.discrepancy, "se": c.se, "floor": c.noise_floor,
                      "per_layer": [float(v) for v in c.per_layer], "seconds": time.time() - t}), flush=True)

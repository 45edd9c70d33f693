#!/bin/bash
# the "after" run: a clean export of HEAD, each file its own scorer process, 4 at a time, in priority order
set -u
R=/work/main/studies/results/2026-11-25d
H=$(git -C /work/main rev-parse HEAD)
T=/tmp/h24/tree_after
rm -rf $T && mkdir -p $T && git -C /work/main archive $H | tar -x -C $T
mkdir -p $R/after
(date -u; echo "code: git archive of $H (clean, no uncommitted edits), PYTHONPATH=$T") > $R/after/code_state.txt
rm -rf /tmp/h24/runner_after && mkdir -p /tmp/h24/runner_after && cp -r /work/main/studies /tmp/h24/runner_after/studies && rm -rf /tmp/h24/runner_after/studies/results
# timing: two fresh processes, one after the other
(cd /tmp/h24/runner_after && for k in 1 2; do uptime; PYTHONPATH=$T /usr/bin/time -f "wall %e s user %U s sys %S s maxrss %M KB" nice -n 10 python -c "import sys; from gift_theory.cli._main import main; sys.exit(main(sys.argv[1:]))" diagnose /tmp/h24/time_16-32-16-8_taps.npz --json --seed 3 --quiet > /tmp/h24/time_after_$k.json; done; uptime) > /tmp/h24/time_after.log 2>&1 &
cd /tmp/h24/runner_after
for item in mesh_taps:mesh_loss_0.npz mesh_taps:mesh_crosstalk_0.npz new_taps:dead_neuron_0.npz new_taps:common_noise_0.npz \
            mesh_notaps:mesh_phase_jitter_0.npz new_notaps:dead_neuron_0.npz new_taps:sin_modulator_0.npz new_taps:bias_drift_0.npz \
            mesh_taps:mesh_phase_jitter_0.npz mesh_notaps:mesh_loss_0.npz new_taps:detector_gain_offset_0.npz new_taps:student_t_layer_0.npz \
            new_taps:last_layer_weight_error_0.npz new_taps:none_0.npz mesh_taps:mesh_bs_ratio_0.npz mesh_taps:mesh_phase_error_0.npz mesh_taps:none_0.npz \
            new_notaps:sin_modulator_0.npz new_notaps:common_noise_0.npz new_notaps:bias_drift_0.npz new_notaps:detector_gain_offset_0.npz \
            new_notaps:student_t_layer_0.npz new_notaps:last_layer_weight_error_0.npz new_notaps:none_0.npz \
            mesh_notaps:mesh_crosstalk_0.npz mesh_notaps:mesh_bs_ratio_0.npz mesh_notaps:mesh_phase_error_0.npz mesh_notaps:none_0.npz; do
  echo $item
done | xargs -P 4 -I{} sh -c 'set=$(echo {} | cut -d: -f1); f=$(echo {} | cut -d: -f2); PYTHONPATH='$T' nice -n 10 python -m studies.blind score /tmp/h24/study/$set --match $f --keep '$R'/after/json_$set > /tmp/h24/after_${set}_$f.jsonl 2> /tmp/h24/after_${set}_$f.log'
date -u > /tmp/h24/after_done

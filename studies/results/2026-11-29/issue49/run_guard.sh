#!/bin/bash
# usage: run6.sh CODE_DIR OUT_DIR  -- gift diagnose --json on the 6 guard files
code=$1; out=$2; mkdir -p $out
F=/tmp/b49/files
for f in open_t/bias_drift_0 open_t/dead_neuron_0 open_nt/none_0 open_nt/common_noise_0 time_t/detector_memory_0 time_nt/intensity_wander_0; do
  set=${f%%/*}; name=${f##*/}
  if [ $name = FIRST ]; then name=$(ls $F/$set | grep npz | head -1); name=${name%.npz}; fi
  ( cd $code && PYTHONPATH=$code nice -n 10 python -m gift_theory.cli._main diagnose $F/$set/$name.npz --json --seed 0 --quiet --no-design > $out/${set}_$name.json 2> $out/${set}_$name.err; echo "$set/$name rc=$?" )
done

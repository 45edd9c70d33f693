#!/usr/bin/env bash
# The commands of docs/lab.md, in order (run in an empty folder; writes chip.npz, law.npz, we.npz and each command's figures in *_gift/COMMAND/).
set -eux
gift simulate --arch 8-16-8-4 --inputs 160 --shots 48 --effect awgn=0.1 --effect shot=0.03 --taps --times --seed 2 --out chip.npz
gift compare chip.npz
gift diagnose chip.npz
gift fit chip.npz --add shot
gift fit chip.npz --add shot --json
gift simulate --arch 8-16-8-4 --inputs 160 --shots 48 --effect awgn=0.1 --effect laplace --taps --seed 2 --out law.npz
gift diagnose law.npz --quiet
gift simulate --arch 8-16-8-4 --inputs 160 --shots 48 --effect awgn=0.1 --effect weight_error=e:0.15,seed:2 --taps --seed 4 --out we.npz
gift fit we.npz --add weight_error

#!/bin/bash
# Old and new code on the same commands: the JSON (but for the seconds and the figure folder),
# its keys' order, the list of figures and every file in the figure folder, byte for byte.
#   OLD=/path/to/old/checkout NEW=/path/to/new/checkout WORK=/tmp/pp bash same_outputs.sh
# WORK holds chip/activation_shape_0.npz and act_shape.py (docs/plugins.md), clean.npz
# (make_clean.py) and T240 a t240 file (studies/results/2026-11-25d/make_time_file.py).
set -u
: "${OLD:?} ${NEW:?} ${WORK:?}"; T240=${T240:-/tmp/t240.npz}; OUT=${OUT:-/tmp/same_outputs}
run() { # pythonpath outdir cmd...
  local pp=$1 out=$2; shift 2
  rm -rf "$out"; mkdir -p "$out"
  ( cd "$WORK" && PYTHONPATH=$pp python -c 'import sys; from gift_theory.cli._main import entry; sys.exit(entry())' \
      "$@" --json --figures "$out/figs" > "$out/out.json" 2> "$out/err.txt" )
}
for c in "diagnose chip/activation_shape_0.npz --quiet" "fit chip/activation_shape_0.npz --plugin act_shape.py --add act_shape --quiet" \
         "compare chip/activation_shape_0.npz" "diagnose $T240 --seed 4 --quiet" "diagnose clean.npz --quiet" \
         "compare clean.npz" "fit clean.npz --add shot --quiet"; do
  name=$(echo $c | cut -d' ' -f1,2 | tr ' /.' '___')
  run "$OLD" "$OUT/old_$name" $c
  run "$NEW" "$OUT/new_$name" $c
  python - "$OUT/old_$name" "$OUT/new_$name" <<'PY'
import filecmp, json, os, sys
a, b = sys.argv[1:]
ja, jb = (json.load(open(f"{d}/out.json")) for d in (a, b))
fig = [[os.path.basename(f) for f in j.pop("figures", [])] for j in (ja, jb)]
for j in (ja, jb):
    j.pop("seconds", None)
fa, fb = sorted(os.listdir(f"{a}/figs")), sorted(os.listdir(f"{b}/figs"))
bad = [f for f in fa if f not in fb or not filecmp.cmp(f"{a}/figs/{f}", f"{b}/figs/{f}", shallow=False)]
print(os.path.basename(b)[4:], "| json", "same" if ja == jb else "DIFFERS", "| key order",
      "same" if list(ja) == list(jb) else "DIFFERS", "| figure list", "same" if fig[0] == fig[1] else "DIFFERS",
      f"| files {len(fa)}/{len(fb)}, differing: {bad}")
PY
done

#!/bin/bash
# old (OLD checkout) and new (NEW) alternately, wall seconds of each command with its figures
: "${OLD:?} ${NEW:?} ${WORK:?}"; T240=${T240:-/tmp/t240.npz}
cd "$WORK"
t() { # label pythonpath cmd...
  local lab=$1 pp=$2; shift 2
  rm -rf /tmp/tfig; /usr/bin/time -f "$lab %e" env PYTHONPATH=$pp python -c 'import sys; from gift_theory.cli._main import entry; sys.exit(entry())' "$@" --figures /tmp/tfig > /dev/null 2>/tmp/terr; tail -1 /tmp/terr
}
for i in 1 2 3; do
  t "t240-old" "$OLD" diagnose "$T240" --seed 4 --quiet
  t "t240-new" "$NEW" diagnose "$T240" --seed 4 --quiet
done
for i in 1 2; do
  t "fit-old" "$OLD" fit chip/activation_shape_0.npz --plugin act_shape.py --add act_shape --quiet
  t "fit-new" "$NEW" fit chip/activation_shape_0.npz --plugin act_shape.py --add act_shape --quiet
  t "clean-old" "$OLD" diagnose clean.npz --quiet
  t "clean-new" "$NEW" diagnose clean.npz --quiet
  t "cmp-old" "$OLD" compare chip/activation_shape_0.npz
  t "cmp-new" "$NEW" compare chip/activation_shape_0.npz
done

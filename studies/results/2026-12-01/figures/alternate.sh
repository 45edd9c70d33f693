#!/bin/bash
# Two checkouts alternately on one command with its figures (fresh processes, wall seconds):
#   alternate.sh OLD_PYTHONPATH NEW_PYTHONPATH N ARGS...
old=$1; new=$2; n=$3; shift 3
for i in $(seq $n); do
  for which in old new; do
    pp=$([ $which = old ] && echo $old || echo $new)
    rm -rf /tmp/wf/ab_figs
    s=$(date +%s.%N)
    PYTHONPATH=$pp python -c 'import sys; from gift_theory.cli._main import entry; sys.exit(entry())' "$@" --figures /tmp/wf/ab_figs > /dev/null 2>&1
    e=$(date +%s.%N)
    echo "$which $(echo "$e - $s" | bc)"
  done
done

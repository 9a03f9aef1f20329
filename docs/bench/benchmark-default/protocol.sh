#!/usr/bin/env bash
# docs/bench/benchmark-default/protocol.sh A B OUT: dsm benchmark at its default size: the session's first commit (A) and its last (B), interleaved
# A B A B on this machine, each a fresh process; CPU seconds (user + sys of the process and its
# children) and wall seconds from GNU time.
set -u
A=$1; B=$2; OUT=$3
mkdir -p $OUT
ROOT=$(cd "$(dirname "$0")/../../.." && pwd)
cd "$ROOT"
for c in $A $B; do
  [ -d $OUT/tree-$c ] || git worktree add -q --detach $OUT/tree-$c $c
done
for round in 1 2; do
  for c in $A $B; do
    rm -rf $OUT/run-$c-$round
    ( cd $OUT/tree-$c && PYTHONPATH=$OUT/tree-$c:$OUT/tree-$c/plugins /usr/bin/time -f "%U %S %e" -o $OUT/time-$c-$round \
        "$ROOT/.venv/bin/python" -m dsm benchmark --suite dsm-bench-4 --out $OUT/run-$c-$round > $OUT/log-$c-$round 2>&1 )
    echo "$c $round $(cat $OUT/time-$c-$round)" >> $OUT/times.txt
  done
done
echo done >> $OUT/times.txt

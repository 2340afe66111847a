#!/bin/bash
# A landing eval campaign with GNU parallel over machines that share a directory (NFS)
# or on one machine: one shard per job slot; `--retries 2` re-flies what a failed shard
# did not write. Then `landing eval merge "$OUT" --expect "$RUNS"` prints the table.
#
#   deploy/batch/parallel-eval.sh 8                 # 8 shards on this machine
#   SSHLOGINS=host1,host2 deploy/batch/parallel-eval.sh 16
set -euo pipefail
N=${1:?usage: parallel-eval.sh SHARDS}
RUNS=${RUNS:-300}
OUT=${OUT:-$PWD/eval-out}
remote=()
[ -n "${SSHLOGINS:-}" ] && remote=(--sshlogin "$SSHLOGINS" --workdir "$PWD")
seq 1 "$N" | parallel "${remote[@]}" --retries 2 --halt now,fail=1 \
  ./target/release/landing eval --runs "$RUNS" --seed 1 --jobs 1 --tracks 0 \
  --shard {}/"$N" --out "$OUT"
./target/release/landing eval merge "$OUT" --expect "$RUNS"

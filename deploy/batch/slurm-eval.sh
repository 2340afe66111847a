#!/bin/bash
# A landing eval campaign as a Slurm job array: task K of N flies shard K/N into the
# shared directory $OUT; a requeued task skips the runs already written. Then
#   landing eval merge "$OUT" --expect "$RUNS"
# gathers the table (docs/eval.md).
#
#   sbatch --array=1-10 deploy/batch/slurm-eval.sh
#
#SBATCH --job-name=landing-eval
#SBATCH --cpus-per-task=1
#SBATCH --mem=1G
#SBATCH --time=02:00:00
#SBATCH --requeue
set -euo pipefail
RUNS=${RUNS:-300}
OUT=${OUT:-$PWD/eval-out}
N=${SLURM_ARRAY_TASK_COUNT:?run as a job array: sbatch --array=1-N}
K=${SLURM_ARRAY_TASK_ID:?run as a job array: sbatch --array=1-N}
exec ./target/release/landing eval --runs "$RUNS" --seed 1 --jobs 1 --tracks 0 \
  --shard "$K/$N" --out "$OUT"

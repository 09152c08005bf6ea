#!/usr/bin/env bash
# One assignment's batch as a Slurm job array: array task K of N grades shard K/N.
#   sbatch --array=1-8 deploy/slurm/grade_array.sh ID SUBMISSIONS OUT
# run from the course checkout (or with COURSE=/path/to/it), which every node sees on a shared file
# system with its .venv (make setup there); SUBMISSIONS and OUT are relative to it or absolute.
# deploy/slurm/submit.sh submits this array and the merge that runs after it.
#SBATCH --job-name=grade --cpus-per-task=2 --mem=8G --time=02:00:00
#SBATCH --output=slurm-%A_%a.out
set -euo pipefail
if [ $# -ne 3 ]; then echo "usage: sbatch --array=1-N $0 ID SUBMISSIONS OUT" >&2; exit 2; fi
assignment=$1 submissions=$2 out=$3
: "${SLURM_ARRAY_TASK_ID:?not an array task: submit with sbatch --array=1-N}"
n=${SLURM_ARRAY_TASK_COUNT}
if [ "${SLURM_ARRAY_TASK_MIN}" != 1 ] || [ "${SLURM_ARRAY_TASK_MAX}" != "$n" ]; then
    echo "the array must be --array=1-N (task K grades shard K of N), not ${SLURM_ARRAY_TASK_MIN}-${SLURM_ARRAY_TASK_MAX}" >&2
    exit 2
fi
cd "${COURSE:-${SLURM_SUBMIT_DIR:-.}}"
exec .venv/bin/python -m autograder batch "$assignment" "$submissions" --out "$out" \
    --jobs "${JOBS:-${SLURM_CPUS_PER_TASK:-2}}" --shard "${SLURM_ARRAY_TASK_ID}/$n"

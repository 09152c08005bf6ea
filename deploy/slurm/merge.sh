#!/usr/bin/env bash
# The shards of a batch joined into one gradebook, OUT/gradebook.csv, once every array task succeeded:
#   sbatch --dependency=afterok:<array job id> deploy/slurm/merge.sh ID OUT
# merge refuses, saying why and writing nothing, while a shard is missing or unfinished.
#SBATCH --job-name=merge --cpus-per-task=1 --mem=2G --time=00:30:00
#SBATCH --output=slurm-%j.out
set -euo pipefail
if [ $# -ne 2 ]; then echo "usage: sbatch $0 ID OUT" >&2; exit 2; fi
cd "${COURSE:-${SLURM_SUBMIT_DIR:-.}}"
exec .venv/bin/python -m autograder merge "$1" "$2" --out "$2"

#!/usr/bin/env bash
# Grade one assignment on a Slurm cluster: an array of N shards, then the merge, which Slurm starts only
# when every shard has succeeded (a shard whose grader failed on a submission exits non-zero: submit
# again and only what is missing is graded).
#   deploy/slurm/submit.sh ID SUBMISSIONS OUT N [sbatch options, for both jobs...]
# e.g. deploy/slurm/submit.sh hw1_imitation submitted grading/hw1_imitation 8 --partition=cpu
set -euo pipefail
if [ $# -lt 4 ]; then echo "usage: $0 ID SUBMISSIONS OUT N [sbatch options...]" >&2; exit 2; fi
here=$(cd "$(dirname "$0")" && pwd)
assignment=$1 submissions=$2 out=$3 n=$4
shift 4
array=$(sbatch --parsable --array=1-"$n" "$@" "$here/grade_array.sh" "$assignment" "$submissions" "$out")
array=${array%%;*}
merge=$(sbatch --parsable --dependency=afterok:"$array" "$@" "$here/merge.sh" "$assignment" "$out")
merge=${merge%%;*}
echo "grading $assignment: job array $array ($n shards); merge: job $merge, once they all succeed"
echo "$array $merge"

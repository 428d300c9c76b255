#!/usr/bin/env bash
# Submit a raysweep sweep to Slurm as N array tasks (one shard each, every
# task with its own raysweepd on loopback) plus a merge job that runs when
# all of them succeeded. Prints "ARRAY_JOB MERGE_JOB".
#
#   docker/slurm/submit.sh --shards N --out DIR [--cpus C] [--max-running K]
#                          SCENE [raysweep sweep options]
#
#   --shards N        number of shards = array tasks (0..N-1)
#   --out DIR         shards in DIR/shard-I, the result in DIR/merged, logs in DIR/logs
#   --cpus C          CPUs (render threads) per task (default 1)
#   --max-running K   at most K tasks at once (sbatch --array=0-(N-1)%K)
#   SCENE             a scene file (.json or .xml), pushed by every task
#   sweep options     as for `raysweep sweep` (--grid, --contexts, --spp, --seed,
#                     --sensor, --set, --format), without --shard and -o
#
# Other sbatch settings come from sbatch's own environment variables
# (SBATCH_PARTITION, SBATCH_TIMELIMIT, SBATCH_ACCOUNT, ...). The scripts
# must be readable on the compute nodes (a shared file system), and
# raysweepd and raysweep installed there (or RAYSWEEP_BIN_DIR set: sbatch
# exports the submitting environment).
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
die() {
  echo "submit.sh: $*" >&2
  exit 2
}
shards='' out='' cpus=1 limit=''
while [ $# -gt 0 ]; do
  case $1 in
  --shards) shards=${2:-}; shift 2 || die "--shards needs a value" ;;
  --out) out=${2:-}; shift 2 || die "--out needs a value" ;;
  --cpus) cpus=${2:-}; shift 2 || die "--cpus needs a value" ;;
  --max-running) limit=${2:-}; shift 2 || die "--max-running needs a value" ;;
  -h | --help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  *) break ;;
  esac
done
[ $# -ge 1 ] || die "a SCENE file is needed (see --help)"
case $shards in '' | *[!0-9]* | 0*) die "--shards needs a positive integer (got '$shards')" ;; esac
case $cpus in '' | *[!0-9]* | 0*) die "--cpus needs a positive integer (got '$cpus')" ;; esac
case $limit in *[!0-9]* | 0*) die "--max-running needs a positive integer (got '$limit')" ;; esac
[ -n "$out" ] || die "--out DIR is needed"
command -v sbatch >/dev/null || die "sbatch not found: run this on a Slurm login node"
scene=$(realpath -e -- "$1") || die "scene file '$1' not found"
shift
mkdir -p "$out/logs"
out=$(realpath -- "$out")

array=$(sbatch --parsable --array="0-$((shards - 1))${limit:+%$limit}" --cpus-per-task="$cpus" \
  --output="$out/logs/shard-%a.out" \
  "$here/raysweep-shard.sbatch" --shards "$shards" --out "$out" "$scene" "$@")
array=${array%%;*} # "JOBID;CLUSTER" on a multi-cluster setup
merge=$(sbatch --parsable --dependency="afterok:$array" --kill-on-invalid-dep=yes \
  --output="$out/logs/merge.out" \
  "$here/raysweep-merge.sbatch" --shards "$shards" --out "$out")
merge=${merge%%;*}
echo "$array $merge"

#!/usr/bin/env bash
# A sharded bake on Slurm: one array job runs `sylva-bake … --shard I/N` (one
# task per shard), and a job that depends on it runs `sylva-bake merge`.
#
#   deploy/slurm/bake.sh --shards N --out SCENE [--work DIR] [--wait]
#                        [--sbatch "ARGS"] -- bake|demo ARGS…
#
#   --shards N    tasks in the array (default 4)
#   --out SCENE   the merged scene directory
#   --work DIR    where the parts and logs go (default SCENE.parts; on a cluster,
#                 a file system every node sees)
#   --wait        return when the merge has finished; exit 1 if it failed
#   --sbatch ARGS extra sbatch options for both jobs (e.g. "--partition=cpu
#                 --cpus-per-task=8 --mem=8G --time=02:00:00")
#   ARGS…         the `sylva-bake bake` (or `demo`) arguments, without --shard and
#                 --out; an --index-node-tiles or --canopy-cell among them is passed
#                 to merge too
#
# SYLVA_BAKE names the binary (default: sylva-bake on PATH). Prints the two job ids.
set -euo pipefail

shards=4 out="" work="" wait=0 extra=""
while [ $# -gt 0 ]; do
  case "$1" in
    --shards) shards=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --wait) wait=1; shift ;;
    --sbatch) extra=$2; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "bake.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ -n "$out" ] || { echo "bake.sh: --out SCENE is required" >&2; exit 2; }
[ $# -gt 0 ] || { echo "bake.sh: give the sylva-bake command after --, e.g. -- bake --model … --placements trees.csv" >&2; exit 2; }
case "$shards" in ''|*[!0-9]*|0) echo "bake.sh: --shards must be a positive whole number, not '$shards'" >&2; exit 2 ;; esac
for a in "$@"; do
  case "$a" in --shard|--shard=*|--out|--out=*) echo "bake.sh: do not pass $a after --: the script sets it" >&2; exit 2 ;; esac
done
command -v sbatch >/dev/null || { echo "bake.sh: sbatch not found (is this a Slurm login node? deploy/slurm/local-cluster.sh starts one here)" >&2; exit 1; }

bake=${SYLVA_BAKE:-$(command -v sylva-bake || true)}
[ -n "$bake" ] || { echo "bake.sh: sylva-bake not on PATH; set SYLVA_BAKE" >&2; exit 1; }
bake=$(realpath "$bake")
mkdir -p "$(dirname "$out")"
out=$(realpath -m "$out")
work=$(realpath -m "${work:-$out.parts}")
mkdir -p "$work/logs"

# merge needs the shards' --index-node-tiles and --canopy-cell.
merge_extra=()
args=("$@")
for i in "${!args[@]}"; do
  case "${args[$i]}" in
    --index-node-tiles|--canopy-cell)
      [ $((i + 1)) -lt ${#args[@]} ] || { echo "bake.sh: ${args[$i]} needs a value" >&2; exit 2; }
      merge_extra+=("${args[$i]}" "${args[$((i + 1))]}") ;;
    --index-node-tiles=*|--canopy-cell=*) merge_extra+=("${args[$i]}") ;;
  esac
done

# The jobs as bash scripts (quoting of any path survives; sbatch runs them as they are).
parts=()
for ((i = 0; i < shards; i++)); do parts+=("$work/part-$i"); done
rm -f "$work/merged.ok"
{
  echo '#!/bin/bash'
  echo 'set -euo pipefail'
  printf 'exec %s ' "$(printf '%q ' "$bake" "$@")"
  printf -- '--shard "$SLURM_ARRAY_TASK_ID/%d" --out %q/part-"$SLURM_ARRAY_TASK_ID"\n' "$shards" "$work"
} >"$work/shard.sh"
{
  echo '#!/bin/bash'
  echo 'set -euo pipefail'
  printf '%s ' "$(printf '%q ' "$bake" merge "${parts[@]}" "${merge_extra[@]}")"
  printf -- '--out %q\n' "$out"
  # The mark of a merge that finished (a re-run keeps an earlier scene when it fails).
  printf 'touch %q\n' "$work/merged.ok"
} >"$work/merge.sh"

# shellcheck disable=SC2086 # $extra is a list of sbatch options
array=$(sbatch --parsable $extra --job-name=sylva-bake-shard --array=0-$((shards - 1)) \
  --output="$work/logs/shard-%a.log" "$work/shard.sh")
array=${array%%;*}
# shellcheck disable=SC2086
merge=$(sbatch --parsable $extra --job-name=sylva-bake-merge --dependency=afterok:"$array" \
  --kill-on-invalid-dep=yes --output="$work/logs/merge.log" "$work/merge.sh")
merge=${merge%%;*}
echo "array job $array ($shards shards, logs in $work/logs), merge job $merge -> $out"

if [ "$wait" -eq 1 ]; then
  # Until neither job is queued or running (squeue failing now and then is retried).
  fails=0
  while true; do
    if queued=$(squeue -h -o %A 2>/dev/null); then
      fails=0
      grep -qxE "$array|$merge" <<<"$queued" || break
    else
      fails=$((fails + 1))
      [ "$fails" -lt 60 ] || { echo "bake.sh: squeue failed for a minute; jobs $array and $merge" >&2; exit 1; }
    fi
    sleep 1
  done
  if [ ! -f "$work/merged.ok" ]; then
    echo "bake.sh: the merge did not finish, so $out was not written; logs:" >&2
    for f in "$work"/logs/*.log; do echo "== $f" >&2; tail -n 20 "$f" >&2; done
    exit 1
  fi
  echo "merged scene in $out"
fi

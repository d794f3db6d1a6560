#!/bin/bash
# An isotouch sweep under Slurm: a Dask scheduler and single-threaded workers started with
# srun inside this allocation, then `python3 -m isotouch.sweep` on the scheduler's file.
#
#   sbatch --ntasks=33 --cpus-per-task=1 --time=02:00:00 python/slurm_sweep.sh SWEEP.json OUT
#   python/slurm_sweep.sh --dry-run SWEEP.json OUT      # prints what it would start
#
# The allocation's tasks: one for the scheduler, the rest are workers (SLURM_NTASKS - 1).
# OUT must be on a file system every node sees (the scheduler file and results.csv live there);
# a job stopped at its time limit is started again with the same arguments and skips the
# tasks already in OUT/results.csv. ISOTOUCH_PYTHONPATH: where the isotouch package is
# (default: build/python beside this script), on every node.
#SBATCH --job-name=isotouch-sweep
#SBATCH --cpus-per-task=1
set -euo pipefail

dry=0
args=()
for a in "$@"; do
  if [[ "$a" == --dry-run ]]; then dry=1; else args+=("$a"); fi
done
if (( ${#args[@]} < 1 || ${#args[@]} > 2 )); then
  echo "usage: slurm_sweep.sh [--dry-run] SWEEP.json [OUT]" >&2
  exit 2
fi
sweep=${args[0]}
out=${args[1]:-sweep-out}
ntasks=${SLURM_NTASKS:-2}
if (( ntasks < 2 )); then
  echo "slurm_sweep.sh: SLURM_NTASKS: $ntasks: needs at least 2 (a scheduler and a worker)" >&2
  exit 2
fi
workers=$((ntasks - 1))
here=$(cd "$(dirname "$0")" && pwd)
export PYTHONPATH=${ISOTOUCH_PYTHONPATH:-$here/../build/python}
export LP_NUM_THREADS=1  # one compute thread per worker: the allocation gives each one CPU
scheduler_file=$out/scheduler.json

# Runs a command, or with --dry-run prints it (shell-quoted, one per line).
run() {
  if (( dry )); then printf '%q ' "$@" | sed 's/ $//'; echo; else "$@"; fi
}
# The same in the background (killed when this script ends); printed with a trailing '&'.
pids=()
start() {
  if (( dry )); then printf '%q ' "$@"; echo "&"; else "$@" & pids+=($!); fi
}
stop() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap stop EXIT

run mkdir -p "$out"
run rm -f "$scheduler_file"
start srun --ntasks=1 --nodes=1 --cpus-per-task=1 dask-scheduler --scheduler-file "$scheduler_file" --no-dashboard
if (( !dry )); then
  for _ in $(seq 120); do [[ -s "$scheduler_file" ]] && break; sleep 1; done
  [[ -s "$scheduler_file" ]] || { echo "slurm_sweep.sh: no scheduler file $scheduler_file after 120 s" >&2; exit 1; }
fi
start srun --ntasks="$workers" --cpus-per-task=1 dask-worker --scheduler-file "$scheduler_file" \
  --nworkers 1 --nthreads 1 --no-dashboard
# Tasks wait at the scheduler until workers join.
run python3 -m isotouch.sweep "$sweep" --scheduler-file "$scheduler_file" --out "$out"

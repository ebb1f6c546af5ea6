#!/usr/bin/env bash
# CI's smoke run of every script in benchmarks/: each runs once on tiny inputs (simulated here, in a
# temporary folder) with the smallest arguments that still take its main path end to end, so that
# none of them rots between the runs that give benchmarks/RESULTS.md its figures. Nothing it prints
# is a figure. Prints "smoke: NAME ok (S s)" per script (a failing one's log tail on stderr) and
# exits non-zero when any failed. Run from anywhere (it works in the repository root):
#   bash benchmarks/smoke.sh
# The CUDA scripts (bench_gpu.sh, bench_gpu_check.sh: a GPU and wheels) get a syntax check only;
# bench_gpu.py runs its CPU paths. About 5 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH=".${PYTHONPATH:+:$PYTHONPATH}"  # the benchmarks import benchmarks._sweep etc.
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}"
PY=${PYTHON:-python}
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
mkdir -p "$T/logs"
# deblur settings that make a run take seconds (tests/conftest.py's TINY)
TINY=(init.n_points=300 blur.n_samples=3 events.warmup=4 events.pixels=256 optim.iterations=10
      optim.pose_start=5 densify.start=4 densify.every=4 densify.stop=9 output.progress=false
      output.checkpoint_every=0)
T_ALL=$(date +%s.%N)
failed=()

# check NAME [--refuse PATTERN] [--note TEXT] -- COMMAND...: run COMMAND (output to a log), print
# one line; fails on a non-zero exit, or when the output has a line matching PATTERN (scripts
# that report a failed step in their table instead of their exit status).
check() {
  local name=$1 refuse="" note="" rc=0
  shift
  while [ "$1" != "--" ]; do
    case $1 in
      --refuse) refuse=$2; shift 2 ;;
      --note) note=" [$2]"; shift 2 ;;
      *) echo "smoke.sh: check $name: unknown option $1" >&2; exit 2 ;;
    esac
  done
  shift
  local log="$T/logs/$name.log" t0
  t0=$(date +%s.%N)
  "$@" >"$log" 2>&1 || rc=$?
  if [ "$rc" -eq 0 ] && [ -n "$refuse" ] && grep -qE -- "$refuse" "$log"; then
    rc="output matches '$refuse'"
  fi
  local s
  s=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  if [ "$rc" = 0 ]; then
    echo "smoke: $name ok ($s s)$note"
  else
    echo "smoke: $name FAILED (exit $rc, $s s)$note"
    { echo "---- $name: $*"; tail -n 30 "$log"; echo "----"; } >&2
    failed+=("$name")
  fi
}

# ---- tiny inputs: a 48x36 scene (5 frames over 0.4 s), a 20k-event EVT 3.0 file
check setup -- "$PY" -m fusiongs simulate -o "$T/scene" --preset boxes --size 48x36 --duration 0.4 --frames 5 \
  --exposure 0.06 --dvs-rate 500 --blur-samples 6 --supersample 1 --novel 1 --seed 1
check setup-evt3 -- "$PY" -c "import sys; from pathlib import Path
from benchmarks.bench_data import synthetic_evt3_chunks, write_evt3
write_evt3(Path(sys.argv[1]), synthetic_evt3_chunks(20000))" "$T/small.raw"

# ---- helpers (imported by the benchmarks)
check _sweep.py --note "import check" -- "$PY" -c "import benchmarks._sweep"
check tiled_reference.py --note "import check; run by bench_render.py" -- \
  "$PY" -c "import benchmarks.tiled_reference"

# ---- the benchmarks
B=benchmarks
check bench_calibrate.py -- "$PY" $B/bench_calibrate.py --smoke --split test --seeds 1000 \
  --root "$T/calibrate" --deblur --refine --json "$T/calibrate.json" "${TINY[@]}"
check bench_calibrate_speed.py -- "$PY" $B/bench_calibrate_speed.py "$T/scene" --reps 1
check bench_data.py -- "$PY" $B/bench_data.py --n 20000 --repeat 1 --raw "$T/small.raw"
check "bench_data.py --evt3-large" --refuse "DIFFER" -- \
  "$PY" $B/bench_data.py --evt3-large 20000 --tmp "$T"
check bench_deblur.py -- "$PY" $B/bench_deblur.py --smoke --presets boxes --seeds 0 --cfa none,RGGB \
  --out "$T/deblur" "${TINY[@]}"
check bench_walk.py -- "$PY" $B/bench_walk.py --smoke --split tuning --seeds 0 --duration 0.6 --frames 8 \
  --chunks 0,0.3 --root "$T/walk" -- "${TINY[@]}" chunk.overlap=0.1
check bench_scaling.py -- "$PY" $B/bench_scaling.py --smoke --split test --seeds 1000 --cases 48x36:5,64x48:5 \
  --root "$T/scaling" -- "${TINY[@]}"
check bench_event_only_sweep.py -- "$PY" $B/bench_event_only_sweep.py --split test --seeds 1000 \
  --size 48x36 --duration 0.3 --root "$T/event_only" --json "$T/event_only.json" "${TINY[@]}"
check "bench_gpu.py render" --note "CPU: --device cpu" -- \
  "$PY" $B/bench_gpu.py render --device cpu --reps 1 --cases 1
check "bench_gpu.py deblur" -- "$PY" $B/bench_gpu.py deblur smoke "$T/scene" "$T/gpu/run" "${TINY[@]}"
check "bench_gpu.py table" -- "$PY" $B/bench_gpu.py table "$T/gpu/bench_gpu.jsonl"
check "bench_gpu.py profile" -- "$PY" $B/bench_gpu.py profile --skip 1 --steps 2 "$T/scene" "${TINY[@]}"
check bench_holdout_edi_grid.py -- "$PY" $B/bench_holdout_edi_grid.py "$T/scene" --holdout 2 \
  --grid 0.2,0.3 --json "$T/holdout.json"
check bench_poses.py -- "$PY" $B/bench_poses.py --out "$T/poses" --scenes "$T/scene" --deblur "${TINY[@]}"
check bench_projection.py -- "$PY" $B/bench_projection.py --n 500 --reps 1
check bench_render.py -- "$PY" $B/bench_render.py --quick --cases 1
check bench_simulate.py -- "$PY" $B/bench_simulate.py --smoke --events-target 20000
check bench_verbs_memory.py --refuse '\| NO \|' -- "$PY" $B/bench_verbs_memory.py --events 2e4 \
  --size 64x48 --duration 0.5 --iterations 2 --tmp "$T"
# the two strips on the run of "bench_gpu.py deblur" (the real recording's stand-in: the tiny scene)
check cups_strip.py -- "$PY" $B/cups_strip.py "$T/scene" "$T/gpu/run" "$T/cups_strip.jpg" \
  --frames 000000,000002
check novel_strip.py -- "$PY" $B/novel_strip.py "$T/gpu/run" "$T/novel_strip.jpg"
check bench_display_ply.py -- "$PY" $B/bench_display_ply.py "$T/gpu/run" --steps 5 -o "$T/display.ply" \
  --json "$T/display.json"
check bench_gpu.sh --note "bash -n syntax check only: needs a CUDA GPU and wheels" -- bash -n $B/bench_gpu.sh
check bench_gpu_check.sh --note "bash -n syntax check only: needs a CUDA GPU and wheels" -- \
  bash -n $B/bench_gpu_check.sh

total=$(awk -v a="$T_ALL" -v b="$(date +%s.%N)" 'BEGIN { printf "%.0f", b - a }')
if [ "${#failed[@]}" -ne 0 ]; then
  echo "smoke: ${#failed[@]} FAILED ($(IFS=,; echo "${failed[*]}")) in $total s" >&2
  exit 1
fi
echo "smoke: all ok in $total s"

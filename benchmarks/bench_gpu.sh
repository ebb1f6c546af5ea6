#!/usr/bin/env bash
# The CUDA checks and GPU figures in one call on a bare machine with an NVIDIA GPU, nvcc and torch
# (the device machine of benchmarks/RESULTS.md "The GPU path, measured"):
#   bash benchmarks/bench_gpu.sh WHEELS CUPS_SCENE OUT BUDGET_S
# WHEELS: a folder of wheels that the machine lacks (gsplat 1.5.3, kornia, kornia-rs, colour-science,
# imageio-ffmpeg), installed with --no-deps into /tmp/site; CUPS_SCENE: the eslnet_cups recording
# with the pose stage's camera and trajectory written into it (pycolmap is CPU-only and not carried);
# OUT: logs, the JSON lines of benchmarks/bench_gpu.py and a small tarball of every run's metrics;
# BUDGET_S: the script stops starting steps once this many seconds have passed.
# Steps: gsplat's CUDA extension compiles in the background (sm_90) while the two simulated scenes
# are written and a 2-iteration run fills numba's cache (so that the timed runs are a user's second
# run; TORCH_RUN=1 instead trains test seed 1000 fully with the pure-torch backend on CUDA); then
# the CUDA tests, three runs with gsplat (test seed 1000 at 173x130, the real 346x260 recording, an
# event-only 173x130 RGGB scene: tuning seed 6, as timed on the CPU) and the rasteriser benchmark
# (gsplat against torch). On an H200 with TORCH_RUN=1 it took 570 s and missed the last two.
set -u
WHEELS=${1:?wheels folder}
CUPS=${2:?posed eslnet_cups scene}
OUT=${3:?output folder}
BUDGET=${4:-540}
WORK=${WORK:-/tmp/fgs_gpu}
DEV=${DEV:-cuda}       # DEV=cpu EXTRA="optim.iterations=5" WHEELS=-: a dry run of the script on a CPU
EXTRA=${EXTRA:-}
mkdir -p "$OUT" "$WORK"
T0=$(date +%s)
el() { echo "[$(( $(date +%s) - T0 )) s] $*" | tee -a "$OUT/steps.log"; }
left() { echo $(( BUDGET - ($(date +%s) - T0) )); }
pack() { (cd "$WORK" && tar czf "$OUT/runs.tgz" --exclude='*.png' --exclude='*.mp4' --exclude='*.ply' \
          --exclude='*.pt' --exclude='events.h5' --exclude='*.npz' runs 2>/dev/null); }
step() {  # step NAME CAP_S COMMAND...: run with a timeout of min(CAP, time left)
  local name=$1 cap=$2; shift 2
  local t; t=$(left); [ "$t" -gt "$cap" ] && t=$cap
  if [ "$t" -lt 20 ]; then el "SKIP $name (budget)"; return 1; fi
  el "START $name (timeout ${t} s)"
  STEP_TIMEOUT=$t timeout $(( t + 20 )) "$@"; local rc=$?  # bench_gpu.py deblur stops its child at t
  el "END $name rc=$rc"; pack; return $rc
}

if [ "$WHEELS" != "-" ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site \
    "$WHEELS"/*.whl || exit 3
fi
chmod +x /tmp/site/imageio_ffmpeg/binaries/* 2>/dev/null
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv | tee "$OUT/gpu.txt"
python3 -c "import torch, numba, numpy; print('torch', torch.__version__, 'cuda', torch.version.cuda, \
'numba', numba.__version__, 'numpy', numpy.__version__, 'cpus', __import__('os').cpu_count())" | tee -a "$OUT/gpu.txt"
el "installed"

# gsplat's JIT build, in the background; the runs before it is done use backend=torch
( export TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=12; s=$(date +%s);
  python3 -c "from gsplat.cuda._backend import _C; assert _C is not None, 'gsplat did not build'" \
  && echo "gsplat built in $(( $(date +%s) - s )) s" ) > "$OUT/gsplat_build.log" 2>&1 &
GS=$!

step simulate 150 bash -c "python3 -m fusiongs simulate -o $WORK/s1000 --sweep-seed 1000 --split test \
  --threads 2 --overwrite & python3 -m fusiongs simulate -o $WORK/eo6 --sweep-seed 6 --split tuning \
  --size 173x130 --frames 0 --novel 6 --threads 2 --overwrite & wait"
python3 - "$WORK/s1000" <<'EOF' | tee -a "$OUT/gpu.txt"
import hashlib, sys
from pathlib import Path
import h5py
root = Path(sys.argv[1]); h = hashlib.sha256()
with h5py.File(root / "events.h5") as f:
    for k in ("t", "x", "y", "p"):
        h.update(f["events"][k][()].tobytes())
for p in sorted((root / "frames").glob("*.png")):
    h.update(p.read_bytes())
print("s1000 events+frames sha256", h.hexdigest()[:16])
EOF

mkdir -p "$WORK/runs"
B="python3 benchmarks/bench_gpu.py"
if [ "${TORCH_RUN:-0}" = 1 ]; then  # the pure-torch backend on CUDA (H200: 110 s, 33.23 dB)
  step "s1000 torch backend (gsplat building beside it)" 240 \
    $B deblur s1000_torch "$WORK/s1000" "$WORK/runs/s1000_torch" -- device=$DEV $EXTRA backend=torch
else  # a 2-iteration run fills numba's cache, so that the timed runs are a user's second run
  WB=""; [ "$DEV" = cuda ] && WB="backend=torch"  # gsplat is still building
  step "warm-up (numba cache)" 120 $B deblur warmup "$WORK/s1000" "$WORK/warmup" -- device=$DEV \
    $WB optim.iterations=2
fi

el "waiting for gsplat"
while kill -0 $GS 2>/dev/null && [ "$(left)" -gt 260 ]; do sleep 2; done
kill -0 $GS 2>/dev/null && { el "gsplat still building: stopped"; kill $GS; }
cat "$OUT/gsplat_build.log" | tail -5
el "gsplat: $(tail -1 "$OUT/gsplat_build.log")"
BK=""  # auto picks gsplat for CUDA tensors; if it did not build, the torch backend instead
if [ "$DEV" = cuda ] && ! grep -q "gsplat built" "$OUT/gsplat_build.log"; then  # no half-built gsplat
  BK="backend=torch"; rm -rf /tmp/site/gsplat /tmp/site/gsplat-*
fi

step "pytest -m cuda" 150 python3 -m pytest -m cuda -q -p no:cacheprovider \
  tests/render/test_gsplat_parity.py tests/train/test_device_clean.py 2>&1 | tee "$OUT/pytest_cuda.log" | tail -15
step "s1000 auto (gsplat)" 150 $B deblur s1000_auto "$WORK/s1000" "$WORK/runs/s1000_auto" -- device=$DEV $EXTRA $BK
step "eslnet_cups auto" 180 $B deblur cups_auto "$CUPS" "$WORK/runs/cups_auto" -- device=$DEV $EXTRA $BK
step "event-only tuning 6" 180 $B deblur eo6_auto "$WORK/eo6" "$WORK/runs/eo6_auto" -- --config event_only device=$DEV $EXTRA $BK
step "render" 90 $B render --reps 20 2>&1 | tee "$OUT/render.txt"
step "profile (40 iterations)" 90 bash -c "$B profile --skip 20 --steps 20 $WORK/s1000 -- device=$DEV \
  $BK > $WORK/runs/profile.txt 2>&1"  # lands in runs.tgz (OUT holds 8 files at most)
cp "$WORK/runs/bench_gpu.jsonl" "$OUT/" 2>/dev/null
$B table "$WORK/runs/bench_gpu.jsonl" | tee "$OUT/table.md"
el "done"

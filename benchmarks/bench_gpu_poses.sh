#!/usr/bin/env bash
# The CUDA tests and the pose-placement benchmark (benchmarks/bench_pose_placement.py: poses on the
# host against the trajectory on the device, in one process) in one call on a bare machine with an
# NVIDIA GPU, nvcc and torch (benchmarks/RESULTS.md, "The GPU path, poses on the host"):
#   OUT=folder bash benchmarks/bench_gpu_poses.sh WHEELS
# WHEELS: a folder of wheels the machine lacks (gsplat 1.5.3, kornia, kornia-rs, colour-science,
# imageio-ffmpeg), installed with --no-deps into /tmp/site. Session 23 (H200): 376 s.
set -u
WHEELS=${1:?wheels folder}
OUT=${OUT:?output folder}
mkdir -p "$OUT"
T0=$(date +%s); W=/tmp/w; mkdir -p $W
el() { echo "[$(( $(date +%s) - T0 )) s] $*" | tee -a "$OUT/steps.log"; }
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "$WHEELS"/*.whl || exit 3
chmod +x /tmp/site/imageio_ffmpeg/binaries/* 2>/dev/null
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 OMP_WAIT_POLICY=PASSIVE
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.version.cuda)" | tee -a "$OUT/gpu.txt"
el installed
( export TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=12; python3 -c "from gsplat.cuda._backend import _C; assert _C is not None" && echo "gsplat built" ) > "$OUT/gsplat.log" 2>&1 &
GS=$!
python3 -m fusiongs simulate -o $W/s1000 --sweep-seed 1000 --split test --threads 2 --overwrite > $W/sim1.log 2>&1 &
S1=$!
python3 -m fusiongs simulate -o $W/eo6 --sweep-seed 6 --split tuning --size 173x130 --frames 0 --novel 6 --threads 2 --overwrite > $W/sim2.log 2>&1 &
S2=$!
wait $S1 $S2; el "simulated"
timeout 90 python3 -m fusiongs deblur $W/s1000 -o $W/warm output.progress=false optim.iterations=2 device=cuda backend=torch > $W/warm.log 2>&1
el "warm-up rc=$?"
wait $GS; el "gsplat: $(tail -1 $OUT/gsplat.log)"
timeout 160 python3 -m pytest -m cuda -q -p no:cacheprovider tests/render/test_gsplat_parity.py tests/train/test_device_clean.py > "$OUT/pytest_cuda.log" 2>&1
el "pytest rc=$?"; tail -3 "$OUT/pytest_cuda.log"
timeout 130 python3 benchmarks/bench_pose_placement.py $W/s1000 -- device=cuda > "$OUT/deblur.txt" 2>&1
el "deblur bench rc=$?"; tail -6 "$OUT/deblur.txt"
timeout 120 python3 benchmarks/bench_pose_placement.py $W/eo6 --config event_only -- device=cuda optim.iterations=1000 > "$OUT/event_only.txt" 2>&1
el "event-only bench rc=$?"; tail -6 "$OUT/event_only.txt"
el done

#!/usr/bin/env bash
# The GPU inference benchmark on the device machine (see prepare.sh): our wgpu executor,
# rten, onnxruntime and PyTorch (gpu_anchor.py: eager and CUDA graph) side by side in one run
# on the same frame. Writes $OUT/infer.md (the tables) and $OUT/infer.json. Then the whole
# `mg_slam` graph on a 300-frame walking xyz folder written on the device, lockstep,
# recording off, its segmenter on `cpu` and on `wgpu` in turn: $OUT/mg_slam_{cpu,wgpu}.log
# (frames/s and the per-node table; the device has 16 cores, so the `cpu` row is not the
# 2-core figure of docs/benchmarks.md).
set -uo pipefail
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
if [ ! -e /usr/share/vulkan/icd.d/nvidia_icd.json ] && [ -e /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,driver_version,clocks.sm --format=csv | tee "$OUT/gpu.txt"
export DYNAFLOW_REPO=$PWD DYNAFLOW_GPU_ANCHOR=$PWD/.gpu/gpu_anchor.py DYNAFLOW_BENCH_JSON=$OUT/infer.json
export DYNAFLOW_PEERS=/nonexistent RUST_LOG=warn
timeout 420 .gpu/infer-bench "${1:-50}" 2>&1 | grep -v XDG_RUNTIME_DIR | tee "$OUT/infer.md"
if [ -e .gpu/dynaflow.gz ]; then
  gzip -dc .gpu/dynaflow.gz > /tmp/dynaflow && chmod +x /tmp/dynaflow
  /tmp/dynaflow synth --motion xyz --people 2 --frames 300 --seed 7 --out /tmp/walking_xyz > /dev/null
  for backend in cpu wgpu; do
    timeout 120 /tmp/dynaflow run graphs/mg_slam.yaml --input /tmp/walking_xyz --intrinsics fr3 --record none \
      --no-progress --set segmenter.backend=$backend --out "$OUT/mg_slam_$backend" > "$OUT/mg_slam_$backend.log" 2>&1
    echo "mg_slam, segmenter on $backend: $(grep -E '^Completed|^ATE' "$OUT/mg_slam_$backend.log" | tr '\n' ' ')"
    grep -E '^(segmenter|orb|flow) ' "$OUT/mg_slam_$backend.log"
    grep -m1 -i 'falls back' "$OUT/mg_slam_$backend.log" || true
  done
fi

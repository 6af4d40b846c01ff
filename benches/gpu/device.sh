#!/usr/bin/env bash
# The GPU inference benchmark on the device machine (see prepare.sh): our wgpu executor,
# rten, onnxruntime and PyTorch (gpu_anchor.py: eager and CUDA graph) side by side in one run
# on the same frame. Writes $OUT/infer.md (the tables) and $OUT/infer.json.
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

#!/usr/bin/env bash
# Prepare the GPU inference benchmark for a machine with an NVIDIA GPU (the device tool's
# H100/H200), run from the repository root here:
#   benches/gpu/prepare.sh [PATH/TO/gpu_anchor.py]
# then, on the device, with `.gpu` and `.gl` carried:
#   bash benches/gpu/device.sh
# It builds the release bench binary (benches/infer.rs) and the CLI, copies them and PyTorch's
# anchor script into `.gpu/`, and downloads the Vulkan loader packages into `.gl/` (the device image has
# the NVIDIA driver but no loader). Both folders are git-ignored.
set -euo pipefail
anchor=${1:-../shared/peers/gpu_anchor.py}
rm -rf .gpu .gl
mkdir -p .gpu .gl
cargo bench --bench infer --no-run --message-format=json 2>/dev/null \
  | python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "infer" and m.get("executable"):
        print(m["executable"])' | tail -1 | xargs -I{} cp {} .gpu/infer-bench
# Debug info would take the binary over the 64 MiB the device tool carries.
strip .gpu/infer-bench
# The CLI too, for the whole `mg_slam` graph with the segmenter on `cpu` and on `wgpu`
# (stripped and gzipped: about 20 MiB).
cargo build --release --bin dynaflow
install -m 755 target/release/dynaflow .gpu/dynaflow
strip .gpu/dynaflow
gzip -6 .gpu/dynaflow
install -m 644 "$anchor" .gpu/gpu_anchor.py
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
mkdir -p /tmp/amd64/partial
apt-get $o update -qq
(cd .gl && apt-get $o download libvulkan1 >/dev/null)
ls -la .gpu .gl

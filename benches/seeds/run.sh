#!/usr/bin/env bash
# The seed pipelines on generator seeds no constant was chosen on (docs/constants.md):
# every seed graph as written, plus MG-SLAM's geometric-only row and the box-mask form of the
# three graphs that segment (`boxes`: MG-SLAM, PSPNet-SLAM, YOEC-DSLAM), on the synthetic walking
# scene (xyz motion, two people, 300 frames) with each seed, then the mean, min and max ATE
# per graph and variant over the seeds. Usage: benches/seeds/run.sh [OUT] [SEEDS...]
# (default OUT bench-seeds, seeds 1001-1005). Needs the release build (cargo build --release).
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${1:-bench-seeds}"
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1001 1002 1003 1004 1005)
exe="${CARGO_TARGET_DIR:-target}/release/dynaflow"
for s in "${seeds[@]}"; do
  "$exe" bench graphs/orb_baseline.yaml graphs/mg_slam.yaml graphs/yg_slam.yaml graphs/pspnet_slam.yaml \
    graphs/ysag.yaml graphs/yoec_dslam.yaml --variants base,G,boxes --jobs 2 --no-progress \
    --set "camera.seed=$s" --out "$out/seed-$s" >/dev/null
done
python3 benches/seeds/summarise.py "$out" "${seeds[@]}"

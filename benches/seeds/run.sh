#!/usr/bin/env bash
# The seed pipelines on generator seeds no constant was chosen on (docs/constants.md):
# every seed graph as written, plus MG-SLAM's geometric-only row and the box-mask form of the
# three graphs that segment (`boxes`: MG-SLAM, PSPNet-SLAM, YOEC-DSLAM), on the synthetic walking
# scene (xyz motion, two people, 300 frames) with each seed, then the mean, min and max ATE
# per graph and variant over the seeds. Usage: benches/seeds/run.sh [OUT] [SEEDS...]
# (default OUT bench-seeds, seeds 1001-1005). MOTIONS="xyz halfsphere rpy" runs each camera
# motion (default xyz; one table per motion). Needs the release build (cargo build --release).
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${1:-bench-seeds}"
shift || true
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(1001 1002 1003 1004 1005)
exe="${DYNAFLOW_EXE:-${CARGO_TARGET_DIR:-target}/release/dynaflow}"
graphs="${GRAPHS:-mg_slam yg_slam pspnet_slam ysag yoec_dslam}"
variants="${VARIANTS:-base,G,boxes}"
for m in ${MOTIONS:-xyz}; do
  for s in "${seeds[@]}"; do
    # orb_baseline as written (what every cut is against), then the seed graphs' variants.
    set_args=(--set "camera.seed=$s" --set "camera.motion=$m")
    "$exe" bench graphs/orb_baseline.yaml --variants base --no-progress "${set_args[@]}" \
      --out "$out/$m/seed-$s/baseline" >/dev/null || echo "seed $s, $m: orb_baseline failed" >&2
    # shellcheck disable=SC2046
    "$exe" bench $(printf 'graphs/%s.yaml ' $graphs) --variants "$variants" --jobs 2 --no-progress \
      "${set_args[@]}" --out "$out/$m/seed-$s/graphs" >/dev/null \
      || echo "seed $s, $m: some runs failed (their rows say why)" >&2
  done
  echo "### $m"
  python3 benches/seeds/summarise.py "$out/$m" "${seeds[@]}"
done

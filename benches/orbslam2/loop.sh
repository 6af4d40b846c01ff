#!/usr/bin/env bash
# Loop closing next to the real ORB-SLAM2. ORB-SLAM2 (raulmur/ORB_SLAM2,
# GPLv3; built headless by ../shared/peers/orbslam2/build.sh, never vendored) runs its RGB-D
# example `rgbd_tum` on a synthetic walk around the room that comes back to its start
# (`dynaflow synth --motion loop`, 1000 frames, static scene, seed 0, TUM layout); dynaflow runs
# `orb_baseline` (loop closing on) and its `no_loop` variant on the same folder. A benchmark
# script, not CI: ORB-SLAM2 is multi-threaded and not deterministic, so every run is reported.
#
#   benches/orbslam2/loop.sh ORBSLAM_DIR [OUT=/tmp/orbslam2-loop] [RUNS=3]
#
# ORB-SLAM2's ATE is over its final trajectory (CameraTrajectory.txt, loop corrections
# included), scored by evo (SE(3)); ours is `ate_final` (the same rebuild from the final key
# frames), scored by dynaflow's evaluation (= evo, tests/eval.rs). ORB-SLAM2 closed a loop when
# its log says "Loop detected!". Its vocabulary is the peer kit's (DBoW2 k 10 L 5, trained on
# real Kinect and synthetic frames; ORBvoc.txt cannot be obtained here).
set -euo pipefail
ORB="$(cd "${1:?usage: loop.sh ORBSLAM_DIR [OUT] [RUNS]}" && pwd)"
OUT="${2:-/tmp/orbslam2-loop}"
RUNS="${3:-3}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
DF="${DF:-$REPO/target/release/dynaflow}"
[ -x "$DF" ] || { echo "missing: $DF (cargo build --release)" >&2; exit 2; }
mkdir -p "$OUT"; OUT="$(cd "$OUT" && pwd)"
SEQ="$OUT/loop"
[ -s "$SEQ/groundtruth.txt" ] || "$DF" synth --motion loop --people 0 --frames 1000 --seed 0 --out "$SEQ"

PEERS="${PEERS:-$REPO/target/peers}" bash "$ORB/run_peer.sh" "$SEQ" "$OUT/orbslam2" "$RUNS"
echo
printf "system\trun\tATE_final_cm\tloop_closed\n"
for i in $(seq 1 "$RUNS"); do
  R="$OUT/orbslam2/run_$i"
  ate=$(awk '$1=="rmse"{printf "%.2f", $2*100}' "$R/ape.txt" 2>/dev/null || true)
  loops=$(grep -c "Loop detected" "$R/orbslam.log" || true)
  printf "ORB-SLAM2\t%s\t%s\t%s\n" "$i" "${ate:-NA}" "$loops"
done
for variant in "" no_loop; do
  name="orb_baseline${variant:+-$variant}"
  "$DF" run "$REPO/graphs/orb_baseline.yaml" ${variant:+--variant $variant} --input "$SEQ" --intrinsics fr3 \
    --record none --no-progress --out "$OUT/dynaflow" > "$OUT/$name.log" 2>&1
  python3 - "$OUT/dynaflow/$name.summary.json" "$name" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
nodes = {n["node"]: n.get("report") or {} for n in s["nodes"]}
ate = nodes["track"]["ate_final"]["rmse"] * 100
loops = len(nodes.get("closing", {}).get("loops", []))
print(f"dynaflow {sys.argv[2]}\t1\t{ate:.2f}\t{loops}")
PY
done

#!/usr/bin/env bash
# The real ORB-SLAM2 (raulmur/ORB_SLAM2, GPLv3; built headless by ../shared/peers/orbslam2/build.sh,
# never vendored) in its stereo and monocular modes, next to dynaflow's on the same synthetic
# frames. A benchmark script, not CI: ORB-SLAM2 is multi-threaded and
# not deterministic, so every run is reported.
#
#   benches/orbslam2/sensor_modes.sh ORBSLAM_DIR [OUT=/tmp/orbslam2-modes] [RUNS=3]
#
# ORBSLAM_DIR is build.sh's OUT_DIR with the stereo and monocular examples built too:
#   make -C ORBSLAM_DIR/src/build -j2 mono_tum stereo_kitti
# Sequences (static scene, 300 frames, generator seed 0, people 0): `xyz` and `halfsphere`
# written by `dynaflow synth` in the TUM layout (mono_tum reads rgb.txt; depth ignored) and in
# the KITTI layout (stereo_kitti reads image_0/image_1: linked to image_2/image_3), 12 cm.
# Scores: `dynaflow eval` (= evo), Sim(3) for monocular (ORB-SLAM2's mono_tum saves key frames
# only: its ATE is over key frames), SE(3) for stereo (every frame).
set -euo pipefail
ORB="$(cd "${1:?usage: sensor_modes.sh ORBSLAM_DIR [OUT] [RUNS]}" && pwd)"
OUT="${2:-/tmp/orbslam2-modes}"
RUNS="${3:-3}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
DF="$REPO/target/release/dynaflow"
PY="${PY:-$REPO/target/peers/bin/python3}"  # numpy and scipy (scripts/peers.sh's venv)
VOC="$ORB/ORBvoc_k10L5_trained.txt"
for f in "$DF" "$VOC" "$ORB/src/Examples/Monocular/mono_tum" "$ORB/src/Examples/Stereo/stereo_kitti"; do
  [ -e "$f" ] || { echo "missing: $f" >&2; exit 2; }
done
mkdir -p "$OUT"; OUT="$(cd "$OUT" && pwd)"
BASELINE=0.12

# ORB-SLAM2 settings: fr3 intrinsics (the generator's), ORB-SLAM2's TUM ORB parameters.
settings() {  # $1 bf
  cat <<YAML
%YAML:1.0
Camera.fx: 535.4
Camera.fy: 539.2
Camera.cx: 320.1
Camera.cy: 247.6
Camera.k1: 0.0
Camera.k2: 0.0
Camera.p1: 0.0
Camera.p2: 0.0
Camera.width: 640
Camera.height: 480
Camera.fps: 30.0
Camera.bf: $1
Camera.RGB: 1
ThDepth: 40.0
ORBextractor.nFeatures: 1000
ORBextractor.scaleFactor: 1.2
ORBextractor.nLevels: 8
ORBextractor.iniThFAST: 20
ORBextractor.minThFAST: 7
Viewer.KeyFrameSize: 0.05
Viewer.KeyFrameLineWidth: 1
Viewer.GraphLineWidth: 0.9
Viewer.PointSize: 2
Viewer.CameraSize: 0.08
Viewer.CameraLineWidth: 3
Viewer.ViewpointX: 0
Viewer.ViewpointY: -0.7
Viewer.ViewpointZ: -1.8
Viewer.ViewpointF: 500
YAML
}
settings 40.0 > "$OUT/mono.yaml"
settings "$("$PY" -c "print(535.4 * $BASELINE)")" > "$OUT/stereo.yaml"

# KITTI 3x4 rows + times.txt -> TUM.
kitti_to_tum() {  # $1 poses (KITTI) $2 times.txt $3 out
  "$PY" - "$1" "$2" "$3" <<'PY'
import sys
import numpy as np
from scipy.spatial.transform import Rotation
poses = [list(map(float, l.split())) for l in open(sys.argv[1]) if l.strip()]
times = [float(l) for l in open(sys.argv[2]) if l.strip()]
with open(sys.argv[3], "w") as f:
    for t, p in zip(times, poses):
        m = np.array(p).reshape(3, 4)
        q = Rotation.from_matrix(m[:, :3]).as_quat()
        f.write(f"{t:.6f} {m[0,3]:.9f} {m[1,3]:.9f} {m[2,3]:.9f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n")
PY
}

ate() {  # $1 gt $2 est $3 align -> "rmse_cm poses"
  "$DF" eval --gt "$1" --est "$2" --align "$3" --json 2>/dev/null |
    "$PY" -c "import json,sys; d=json.load(sys.stdin); print(f\"{100*d['ate']['rmse']:.2f} {d['matched']}\")" || echo "failed -"
}

printf "mode\tmotion\twho\trun\tate_cm\tposes\n" > "$OUT/summary.tsv"
for motion in xyz halfsphere; do
  TUM="$OUT/tum-$motion"; KIT="$OUT/kitti-$motion"
  [ -f "$TUM/rgb.txt" ] || "$DF" synth --motion "$motion" --people 0 --frames 300 --out "$TUM" 2>/dev/null
  [ -f "$KIT/sequences/00/times.txt" ] || "$DF" synth --format kitti --baseline $BASELINE --motion "$motion" --people 0 --frames 300 --out "$KIT" 2>/dev/null
  SEQ="$KIT/sequences/00"
  ln -sfn image_2 "$SEQ/image_0"; ln -sfn image_3 "$SEQ/image_1"
  kitti_to_tum "$KIT/poses/00.txt" "$SEQ/times.txt" "$KIT/groundtruth.txt"
  for i in $(seq 1 "$RUNS"); do
    R="$OUT/run-$motion-$i"; mkdir -p "$R"
    (cd "$R" && timeout 3600 "$ORB/src/Examples/Monocular/mono_tum" "$VOC" "$OUT/mono.yaml" "$TUM" > mono.log 2>&1) || true
    printf "mono\t%s\tORB-SLAM2\t%s\t%s\n" "$motion" "$i" "$(ate "$TUM/groundtruth.txt" "$R/KeyFrameTrajectory.txt" sim3 | tr ' ' '\t')" >> "$OUT/summary.tsv"
    (cd "$R" && timeout 3600 "$ORB/src/Examples/Stereo/stereo_kitti" "$VOC" "$OUT/stereo.yaml" "$SEQ" > stereo.log 2>&1) || true
    if [ -f "$R/CameraTrajectory.txt" ]; then kitti_to_tum "$R/CameraTrajectory.txt" "$SEQ/times.txt" "$R/stereo_tum.txt"; fi
    printf "stereo\t%s\tORB-SLAM2\t%s\t%s\n" "$motion" "$i" "$(ate "$KIT/groundtruth.txt" "$R/stereo_tum.txt" se3 | tr ' ' '\t')" >> "$OUT/summary.tsv"
  done
  # dynaflow on the same folders (deterministic: one run each).
  D="$OUT/dynaflow-$motion"
  "$DF" run "$REPO/graphs/orb_baseline.yaml" --variant mono --input "$TUM" --record none --no-progress --out "$D" > /dev/null 2>&1 || true
  printf "mono\t%s\tdynaflow\t1\t%s\n" "$motion" "$(ate "$TUM/groundtruth.txt" "$D/orb_baseline-mono.track.trajectory.txt" sim3 | tr ' ' '\t')" >> "$OUT/summary.tsv"
  "$DF" run "$REPO/graphs/orb_baseline.yaml" --variant stereo --input "$SEQ" --record none --no-progress --out "$D" > /dev/null 2>&1 || true
  printf "stereo\t%s\tdynaflow\t1\t%s\n" "$motion" "$(ate "$KIT/groundtruth.txt" "$D/orb_baseline-stereo.track.trajectory.txt" se3 | tr ' ' '\t')" >> "$OUT/summary.tsv"
done
column -t "$OUT/summary.tsv"

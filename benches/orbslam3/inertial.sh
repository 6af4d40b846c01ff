#!/usr/bin/env bash
# The real ORB-SLAM3 (UZ-SLAMLab/ORB_SLAM3 at 4452a3c, GPLv3) in its stereo, stereo-inertial and
# monocular-inertial modes, next to dynaflow's on the same `dynaflow synth --format euroc`
# folders. A benchmark script, not CI: ORB-SLAM3 is multi-threaded and not deterministic, so
# every run is reported.
#
#   benches/orbslam3/inertial.sh ORB3_DIR [OUT=/tmp/orbslam3-vi] [RUNS=3] [SEEDS="5 0 1 2 3"]
#
# ORB3_DIR holds the peer's EuRoC examples, built by you from the unmodified upstream tree (the
# project commits no code of it and no recipe that builds it): bin/stereo_euroc,
# bin/stereo_inertial_euroc, bin/mono_inertial_euroc, and a DBoW2 text vocabulary
# ORB3_DIR/ORBvoc.txt (the official one, or ../shared/peers/orbslam2's trained
# ORBvoc_k10L5_trained.txt: it drives BoW matching, relocalisation and loops, not tracking).
# The build that produced docs/benchmarks.md's figures: upstream's CMakeLists with its viewer
# replaced by a no-op class, the examples started with the viewer off, C++17 throughout.
#
# The settings are the generator's rig (fr3 intrinsics, rectified 12 cm stereo as `Camera.bf`,
# cam0's T_BS as `Tbc`,
# EuRoC's ADIS16448 noise as synth's sensor.yaml states) with ORB-SLAM3's own EuRoC ORB
# parameters (1200 features stereo, 1000 monocular), and `IMU.fastInit: 1`: the peer starts a
# stereo-inertial map only once the mean acceleration of two consecutive frames differs by
# 0.5 m/s^2, which EuRoC's vibrating MAV meets at once and the generator's smooth hand-held
# motion never does (without it: no map, every frame lost). ORB-SLAM3 saves the IMU body's pose in the
# inertial modes and cam0's otherwise: both are turned into cam0 poses (T_wc = T_wb T_bc) and
# scored with `dynaflow eval` (= evo) against the camera ground truth dynaflow's run writes,
# SE(3) alignment (no scale fitted) for every mode; the monocular scale error from a Sim(3) fit.
set -euo pipefail
ORB="$(cd "${1:?usage: inertial.sh ORB3_DIR [OUT] [RUNS] [SEEDS]}" && pwd)"
OUT="${2:-/tmp/orbslam3-vi}"
RUNS="${3:-3}"
SEEDS="${4:-5 0 1 2 3}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
DF="${DF:-$REPO/target/release/dynaflow}"
PY="${PY:-$REPO/target/peers/bin/python3}"  # numpy and scipy (scripts/peers.sh's venv)
VOC="${VOC:-$ORB/ORBvoc.txt}"
for f in "$DF" "$VOC" "$ORB/bin/stereo_euroc" "$ORB/bin/stereo_inertial_euroc" "$ORB/bin/mono_inertial_euroc"; do
  [ -e "$f" ] || { echo "missing: $f" >&2; exit 2; }
done
mkdir -p "$OUT"; OUT="$(cd "$OUT" && pwd)"

# ORB-SLAM3 settings from a folder's own sensor.yaml files, in the peer's first settings format
# (no `File.version`): the only one that reads `IMU.fastInit` (below).
settings() {  # $1 mav0 dir, $2 features -> yaml on stdout
  "$PY" - "$1" "$2" <<'PY'
import re, sys
mav, nfeat = sys.argv[1], int(sys.argv[2])
def read(path):
    text = open(path).read()
    data = lambda key: [float(x) for x in re.search(key + r":[^\[]*\[([^\]]*)\]", text, re.S).group(1).split(",")]
    scalar = lambda key: float(re.search(r"^" + key + r":\s*([-0-9.eE+]+)", text, re.M).group(1))
    return data, scalar
c0, s0 = read(f"{mav}/cam0/sensor.yaml"); c1, _ = read(f"{mav}/cam1/sensor.yaml"); _, si = read(f"{mav}/imu0/sensor.yaml")
fx, fy, cx, cy = c0("intrinsics"); w, h = c0("resolution")
t0, t1 = c0("T_BS"), c1("T_BS")
# baseline: cam1's centre in cam0's frame (R0^T (p1 - p0)); rectified rigs have it on +x
p = [t1[3] - t0[3], t1[7] - t0[7], t1[11] - t0[11]]
b = sum(t0[4 * r + 0] * p[r] for r in range(3))
mat = ", ".join(repr(v) for v in t0)
print(f"""%YAML:1.0
Camera.type: "PinHole"
Camera.fx: {fx}
Camera.fy: {fy}
Camera.cx: {cx}
Camera.cy: {cy}
Camera.k1: 0.0
Camera.k2: 0.0
Camera.p1: 0.0
Camera.p2: 0.0
Camera.width: {int(w)}
Camera.height: {int(h)}
Camera.fps: {int(s0('rate_hz'))}
Camera.bf: {b * fx}
Camera.RGB: 0
ThDepth: 60.0
Tbc: !!opencv-matrix
  rows: 4
  cols: 4
  dt: f
  data: [{mat}]
IMU.NoiseGyro: {si('gyroscope_noise_density')}
IMU.NoiseAcc: {si('accelerometer_noise_density')}
IMU.GyroWalk: {si('gyroscope_random_walk')}
IMU.AccWalk: {si('accelerometer_random_walk')}
IMU.Frequency: {int(si('rate_hz'))}
IMU.fastInit: 1
ORBextractor.nFeatures: {nfeat}
ORBextractor.scaleFactor: 1.2
ORBextractor.nLevels: 8
ORBextractor.iniThFAST: 20
ORBextractor.minThFAST: 7
Viewer.KeyFrameSize: 0.05
Viewer.KeyFrameLineWidth: 1.0
Viewer.GraphLineWidth: 0.9
Viewer.PointSize: 2.0
Viewer.CameraSize: 0.08
Viewer.CameraLineWidth: 3.0
Viewer.ViewpointX: 0.0
Viewer.ViewpointY: -0.7
Viewer.ViewpointZ: -1.8
Viewer.ViewpointF: 500.0""")
PY
}

# ORB-SLAM3's EuRoC trajectory (ns, T_wb or T_wc) -> TUM cam0 poses (s).
to_tum() {  # $1 ORB-SLAM3 trajectory $2 mav0 dir $3 body|camera $4 out
  "$PY" - "$1" "$2" "$3" "$4" <<'PY'
import re, sys
import numpy as np
from scipy.spatial.transform import Rotation as R
src, mav, frame, dst = sys.argv[1:]
text = open(f"{mav}/cam0/sensor.yaml").read()
t_bc = np.array([float(x) for x in re.search(r"T_BS:[^\[]*\[([^\]]*)\]", text, re.S).group(1).split(",")]).reshape(4, 4)
with open(dst, "w") as f:
    for line in open(src):
        v = line.split()
        if len(v) != 8 or line.startswith("#"):
            continue
        t, x = float(v[0]) * 1e-9, np.array([float(s) for s in v[1:]])
        m = np.eye(4); m[:3, :3] = R.from_quat(x[3:]).as_matrix(); m[:3, 3] = x[:3]
        if frame == "body":
            m = m @ t_bc
        q = R.from_matrix(m[:3, :3]).as_quat()
        f.write(f"{t:.9f} {m[0,3]:.9f} {m[1,3]:.9f} {m[2,3]:.9f} {q[0]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f}\n")
PY
}

ate() {  # $1 gt $2 est -> "ate_mm poses scale_err_%"
  local se3 sim3
  se3=$("$DF" eval --gt "$1" --est "$2" --align se3 --json 2>/dev/null) || { echo "failed - -"; return; }
  sim3=$("$DF" eval --gt "$1" --est "$2" --align sim3 --json 2>/dev/null) || sim3='{}'
  "$PY" -c "
import json, sys
a, b = json.loads(sys.argv[1]), json.loads(sys.argv[2])
s = b.get('scale')
print(f\"{1000*a['ate']['rmse']:.1f} {a['matched']} {'-' if s is None else f'{100*abs(s-1):.2f}'}\")" "$se3" "$sim3"
}

printf "seed\tmode\twho\trun\tate_mm\tposes\tscale_err_pct\n" > "$OUT/summary.tsv"
for seed in $SEEDS; do
  SEQ="$OUT/seed$seed"; MAV="$SEQ/mav0"
  [ -f "$MAV/cam0/data.csv" ] || "$DF" synth --format euroc --motion handheld --frames 300 --people 0 --seed "$seed" --out "$SEQ" > /dev/null 2>&1
  grep -v '^#' "$MAV/cam0/data.csv" | cut -d, -f1 > "$SEQ/times.txt"
  settings "$MAV" 1200 > "$SEQ/stereo.yaml"
  settings "$MAV" 1000 > "$SEQ/mono.yaml"
  # dynaflow (deterministic: one run per mode); its ground truth is cam0's poses.
  D="$SEQ/dynaflow"
  for v in stereo stereo_inertial mono_inertial; do
    "$DF" run "$REPO/graphs/orb_baseline.yaml" --variant "$v" --input "$SEQ" --record none --no-progress --out "$D" > /dev/null 2>&1 || true
    printf "%s\t%s\tdynaflow\t1\t%s\n" "$seed" "$v" "$(ate "$D/orb_baseline-$v.track.groundtruth.txt" "$D/orb_baseline-$v.track.final_trajectory.txt" | tr ' ' '\t')" >> "$OUT/summary.tsv"
  done
  GT="$D/orb_baseline-stereo.track.groundtruth.txt"
  for i in $(seq 1 "$RUNS"); do
    for mode in stereo stereo_inertial mono_inertial; do
      R="$SEQ/orbslam3-$mode-$i"; rm -rf "$R"; mkdir -p "$R"
      yaml="$SEQ/stereo.yaml"; frame=body
      [ "$mode" = mono_inertial ] && yaml="$SEQ/mono.yaml"
      [ "$mode" = stereo ] && frame=camera
      (cd "$R" && timeout 1800 "$ORB/bin/${mode}_euroc" "$VOC" "$yaml" "$SEQ" "$SEQ/times.txt" > run.log 2>&1) || true
      if [ -s "$R/CameraTrajectory.txt" ]; then
        to_tum "$R/CameraTrajectory.txt" "$MAV" "$frame" "$R/cam0.tum"
        printf "%s\t%s\tORB-SLAM3\t%s\t%s\n" "$seed" "$mode" "$i" "$(ate "$GT" "$R/cam0.tum" | tr ' ' '\t')" >> "$OUT/summary.tsv"
      else
        printf "%s\t%s\tORB-SLAM3\t%s\tfailed\t0\t-\n" "$seed" "$mode" "$i" >> "$OUT/summary.tsv"
      fi
    done
  done
done
column -t "$OUT/summary.tsv"

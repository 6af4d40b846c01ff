#!/usr/bin/env bash
# Whole-system speed next to the real ORB-SLAM2. On one TUM-layout folder (the walking
# xyz copy of docs/benchmarks.md: `dynaflow synth --motion xyz --people 2 --frames 300 --seed 7`,
# or any folder given as SEQ), in one run of this script:
#   - ORB-SLAM2's `rgbd_tum` (raulmur/ORB_SLAM2, GPLv3; built headless by
#     ../shared/peers/orbslam2/build.sh, never vendored), RUNS times: its own per-frame tracking
#     time (median and mean, printed by rgbd_tum; local mapping and loop closing run in their own
#     threads beside it) and its ATE (evo, SE(3)). rgbd_tum replays at the sequence's frame rate,
#     so its wall time is the sequence's length, not its speed.
#   - dynaflow's `mg_slam` and `orb_baseline`, lockstep, recording off, and `mg_slam` recording
#     .rrd + MCAP: frames/s (frames / wall time, both cores), ms per frame, the end-to-end age of
#     a frame at `track` (mean, p50, p95: source to pose, queueing included), the per-node
#     latency table, and the ATE.
#   - ORB-SLAM2's CPU time per frame over all its threads (user + system, start-up subtracted)
#     next to ours, on this folder and on the same motion without people.
#   - with LONG=N (e.g. 3000): mg_slam on an N-frame folder of the same scene and its peak RSS next
#     to the 300-frame run's, to show memory stays flat.
# A benchmark script, not CI: ORB-SLAM2 is multi-threaded and not deterministic, so every run is
# reported; both sides share the machine's two cores.
#
#   benches/orbslam2/speed.sh ORBSLAM_DIR [OUT=/tmp/dynaflow-speed] [RUNS=3]
set -euo pipefail
ORB="$(cd "${1:?usage: speed.sh ORBSLAM_DIR [OUT] [RUNS]}" && pwd)"
OUT="${2:-/tmp/dynaflow-speed}"
RUNS="${3:-3}"
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
DF="${DF:-$REPO/target/release/dynaflow}"
[ -x "$DF" ] || { echo "missing: $DF (cargo build --release)" >&2; exit 2; }
mkdir -p "$OUT"; OUT="$(cd "$OUT" && pwd)"
SEQ="${SEQ:-$OUT/walking_xyz}"
[ -s "$SEQ/groundtruth.txt" ] || "$DF" synth --motion xyz --people 2 --frames 300 --seed 7 --out "$SEQ" > /dev/null

echo "== ORB-SLAM2 rgbd_tum on $SEQ ($RUNS runs)"
PEERS="${PEERS:-$REPO/target/peers}" bash "$ORB/run_peer.sh" "$SEQ" "$OUT/orbslam2" "$RUNS" > "$OUT/orbslam2.log" 2>&1 \
  || { echo "ORB-SLAM2 failed: $OUT/orbslam2.log" >&2; exit 1; }
printf "%-28s %6s %14s %14s %10s\n" "system" "run" "median ms/fr" "mean ms/fr" "ATE cm"
awk -F'\t' 'NR>1 { printf "%-28s %6s %14s %14s %10s\n", "ORB-SLAM2 (tracking thread)", $1, $8, $9, ($2=="NA"?"NA":sprintf("%.2f", $2*100)) }' \
  "$OUT/orbslam2/summary.tsv"

# ORB-SLAM2's CPU time per frame, all its threads: one run on every frame and one on the first
# 10 (vocabulary loading and start-up), the difference over the frames in between.
cpu_run() {  # $1 sequence  $2 associations file -> "user+sys seconds"
  local d; d=$(mktemp -d)
  ( cd "$d" && /usr/bin/time -f "%U %S" -o "$d/time" "$ORB/src/Examples/RGB-D/rgbd_tum" "$ORB/ORBvoc_k10L5_trained.txt" \
      "$ORB/TUM3.yaml" "$1" "$2" > /dev/null 2>&1 ) || true
  awk '{print $1 + $2}' "$d/time"; rm -rf "$d"
}
orbslam_cpu() {  # $1 sequence folder  $2 label
  python3 "$ORB/associate.py" "$1/rgb.txt" "$1/depth.txt" --max_difference 0.02 > "$OUT/assoc_all.txt"
  head -10 "$OUT/assoc_all.txt" > "$OUT/assoc_10.txt"
  local full start n
  full=$(cpu_run "$1" "$OUT/assoc_all.txt"); start=$(cpu_run "$1" "$OUT/assoc_10.txt"); n=$(wc -l < "$OUT/assoc_all.txt")
  python3 -c "import sys; f,s,n=float(sys.argv[1]),float(sys.argv[2]),int(sys.argv[3]); print(f'ORB-SLAM2 CPU, all threads, {sys.argv[4]}: {f:.1f} s on {n} frames, {s:.1f} s on 10 (start-up): {1000*(f-s)/(n-10):.1f} core-ms per frame')" "$full" "$start" "$n" "$2"
}
orbslam_cpu "$SEQ" "walking people"

report() {  # $1 summary.json  $2 label  $3 "peak-RSS-KiB user-s sys-s" (GNU time)
  python3 - "$1" "$2" $3 <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
cpu = float(sys.argv[4]) + float(sys.argv[5])
frames, wall = s["frames"], s["wall_s"]
nodes = {n["node"]: n for n in s["nodes"]}
age = nodes["track"]["age"]
ate = s["ate"]["rmse"]
print(f"{sys.argv[2]}: {frames} frames in {wall:.2f} s = {frames / wall:.1f} frames/s, {1000 * wall / frames:.2f} ms per frame; "
      f"age at track mean {age['mean_ms']:.0f} / p50 {age['p50_ms']:.0f} / p95 {age['p95_ms']:.0f} ms; "
      f"ATE {ate * 100:.2f} cm; CPU {cpu:.1f} s = {cpu / wall:.2f} cores busy, {1000 * cpu / frames:.1f} core-ms per frame; "
      f"peak RSS {int(sys.argv[3]) / 1024:.0f} MiB")
print(f"  {'node':<14} {'op':<16} {'frames':>6} {'mean ms':>8} {'p50 ms':>8} {'p95 ms':>8} {'busy s':>7}")
for n in s["nodes"]:
    if n["frames"]:
        l = n["latency"]
        print(f"  {n['node']:<14} {n['op']:<16} {n['frames']:>6} {l['mean_ms']:>8.2f} {l['p50_ms']:>8.2f} {l['p95_ms']:>8.2f} {n['busy_s']:>7.2f}")
PY
}

run_graph() {  # $1 graph  $2 record  $3 seq  $4 label
  local dir="$OUT/dynaflow/$4"
  rm -rf "$dir"; mkdir -p "$dir"
  /usr/bin/time -f "%M %U %S" -o "$dir/rss" "$DF" run "$REPO/graphs/$1.yaml" --input "$3" --intrinsics fr3 --record "$2" \
    --no-progress --out "$dir" > "$dir/log" 2>&1 || { echo "$4 failed: $dir/log" >&2; exit 1; }
  report "$dir/$1.summary.json" "$4" "$(tail -1 "$dir/rss")"
}

echo
echo "== dynaflow, lockstep, 2 cores"
run_graph mg_slam none "$SEQ" "mg_slam, recording off"
run_graph orb_baseline none "$SEQ" "orb_baseline, recording off"
run_graph mg_slam rrd,mcap "$SEQ" "mg_slam, .rrd + MCAP"
if [ -n "${LONG:-}" ]; then
  LSEQ="$OUT/walking_xyz_$LONG"
  [ -s "$LSEQ/groundtruth.txt" ] || "$DF" synth --motion xyz --people 2 --frames "$LONG" --seed 7 --out "$LSEQ" > /dev/null
  run_graph mg_slam none "$LSEQ" "mg_slam, $LONG frames, recording off"
fi

# The same cost on the static scene (no people: ORB-SLAM2 does not fail there).
SSEQ="$OUT/static_xyz"
[ -s "$SSEQ/groundtruth.txt" ] || "$DF" synth --motion xyz --people 0 --frames 300 --seed 7 --out "$SSEQ" > /dev/null
echo
echo "== static scene (people 0)"
orbslam_cpu "$SSEQ" "static scene"
run_graph mg_slam none "$SSEQ" "mg_slam, static scene, recording off"
run_graph orb_baseline none "$SSEQ" "orb_baseline, static scene, recording off"

#!/usr/bin/env bash
# Trains the default vocabulary, slam/vocabulary/default.voc (see slam/vocabulary/SOURCE.md):
# every 5th frame of three 600-frame synthetic sequences of generator seed 31 (motions
# halfsphere, rpy and xyz, two walking people; seed 31 is used by no evaluation) and the nine
# real Kinect frames the repository ships under tests/fixtures (slambook2, MIT).
#   scripts/train_vocabulary.sh [OUT]       (needs target/release/dynaflow)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-slam/vocabulary/default.voc}"
bin=target/release/dynaflow
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
images=()
for motion in halfsphere rpy xyz; do
  "$bin" synth --motion "$motion" --people 2 --frames 600 --seed 31 --out "$tmp/$motion" >/dev/null
  mapfile -t frames < <(ls "$tmp/$motion"/rgb/*.png | awk 'NR % 5 == 1')
  images+=("${frames[@]}")
done
images+=(tests/fixtures/slambook2_dense_rgbd/color/*.png tests/fixtures/slambook2_rgbd_pair/rgb/*.png tests/fixtures/slambook2_lk_pair/*.png)
"$bin" vocab train --k 10 --levels 5 --features 1000 --seed 0 --out "$out" "${images[@]}"

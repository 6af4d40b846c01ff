#!/usr/bin/env bash
# The README's test command: installs the peers (scripts/peers.sh), runs the whole test suite
# with every peer comparison required, and ends with one line naming every comparison that
# was skipped. Extra arguments go to `cargo test` (e.g. `scripts/test.sh --test eval`).
#   DYNAFLOW_SKIP_PEERS=evo,opencv,...  skips those peers' comparisons on purpose
#   (peers: opencv, evo, onnxruntime, octomap, rerun, mcap, gpu, chromium; or all).
set -uo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-$PWD/target}"
export DYNAFLOW_PEERS="${DYNAFLOW_PEERS:-$target/peers}"
t0=$(date +%s)
bash scripts/peers.sh || { echo "error: installing the peers failed (scripts/peers.sh)" >&2; exit 1; }
t1=$(date +%s)
export DYNAFLOW_REQUIRE_PEERS=1
skips="$target/peer-skips"
rm -rf "$skips" && mkdir -p "$skips"
export DYNAFLOW_SKIP_LOG="$skips"
# `--features zenoh,python`: graphs across machines and Python operators are built and tested
# too (the default build has neither zenoh nor libpython; tests/dependencies.rs checks that).
# PyO3 builds against Debian's Python (python3-dev, installed by peers.sh), whose libpython the
# binary finds where it runs.
if [ -z "${PYO3_PYTHON:-}" ] && [ -x /usr/bin/python3 ]; then export PYO3_PYTHON=/usr/bin/python3; fi
log="$target/test-output.txt"
: > "$log"
# Built first, so the build's time is told apart from the tests'.
cargo test --workspace --release --features zenoh,python --no-run "$@" 2>&1 | tee "$target/build-output.txt"
status=${PIPESTATUS[0]}
# dynaflow as a Python package: `pip install .` into a fresh virtual environment (maturin,
# pinned, builds the extension module into the same target folder; matplotlib for the
# ablation example); tests/python.rs imports it from there.
pkg="$target/py-package"
if [ "$status" -eq 0 ]; then
  rm -rf "$pkg" && python3 -m venv "$pkg" &&
    "$pkg/bin/pip" install -q --disable-pip-version-check maturin==1.16.0 matplotlib==3.11.2 \
      "numpy==$(sed -n 's/^numpy==//p' tests/peers/requirements.txt)" &&
    PATH="$pkg/bin:$PATH" "$pkg/bin/pip" install -q --disable-pip-version-check --no-build-isolation . 2>&1 | tee -a "$target/build-output.txt"
  status=${PIPESTATUS[0]}
  [ "$status" -eq 0 ] || echo "error: pip install . failed" >&2
  export DYNAFLOW_PY_PACKAGE="$pkg"
fi
t2=$(date +%s)
if [ "$status" -eq 0 ]; then
  cargo test --workspace --release --no-fail-fast --features zenoh,python "$@" 2>&1 | tee "$log"
  status=${PIPESTATUS[0]}
fi
t3=$(date +%s)
# The wall time of each test binary, slowest first (from cargo's own "finished in" lines).
awk '/^ *Running / { bin = $2; if (bin == "unittests") { n = split($NF, a, "/"); b = a[n]; sub(/-[0-9a-f]+\)$/, "", b); bin = "unittests " b } }
     /^ *Doc-tests / { bin = "doc-tests " $2 }
     /^test result:/ { t = $NF; sub(/s$/, "", t); printf "%8.1f s  %s\n", t, bin }' "$log" |
  sort -rn | awk 'BEGIN { print "test binaries by wall time:" } { print; total += $1 } END { printf "%8.1f s  in all\n", total }'

echo "wall time: peers $((t1 - t0)) s, build $((t2 - t1)) s, tests $((t3 - t2)) s"

list="$(cat "$skips"/*.txt 2>/dev/null | sort -u)"
if [ -z "$list" ]; then
  echo "peer comparisons skipped: none"
else
  echo "peer comparisons skipped ($(printf '%s\n' "$list" | wc -l)): $(printf '%s\n' "$list" | paste -sd';' - | sed 's/;/; /g')"
fi
exit $status

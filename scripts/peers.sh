#!/usr/bin/env bash
# Installs the peers the tests compare against and prints their versions. Idempotent; the
# README's test command (scripts/test.sh) and .ci/run call it.
#   Python peers: a venv at $DYNAFLOW_PEERS (default: <target folder>/peers) with
#     tests/peers/requirements.txt (every version pinned);
#   Debian packages, when root (or with sudo): OctoMap 1.9 (liboctomap-dev, octomap-tools),
#     g++ (builds the OctoMap peer), Mesa's lavapipe (a software Vulkan adapter for the GPU
#     kernels on a machine without a GPU), Chromium (the rerun web viewer, checked as a user
#     sees it: tests/viewer.rs; software rendering).
# DYNAFLOW_SKIP_PEERS=all installs nothing (the tests then name every skipped comparison).
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-$PWD/target}"
venv="${DYNAFLOW_PEERS:-$target/peers}"
req="tests/peers/requirements.txt"
case ",${DYNAFLOW_SKIP_PEERS:-}," in *,all,*) echo "peers: none installed (DYNAFLOW_SKIP_PEERS=all)"; exit 0 ;; esac

# openssl: the certificates of the split-run-over-TLS test (tests/distributed.rs); python3-dev:
# the libpython and headers PyO3 builds the `python` feature against; tmux: the terminal
# `dynaflow top` is checked in (tests/cli.rs).
debs="liboctomap-dev octomap-tools g++ mesa-vulkan-drivers libvulkan1 chromium openssl python3-dev tmux"
need=""
for p in $debs; do dpkg -s "$p" >/dev/null 2>&1 || need="$need $p"; done
if [ -n "$need" ]; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
      echo "peers: not root and no sudo: install$need with your package manager" >&2
    fi
  fi
  if [ "$(id -u)" -eq 0 ] || [ -n "$sudo" ]; then
    $sudo apt-get update -q >/dev/null
    # shellcheck disable=SC2086
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends $need >/dev/null
  fi
fi

# The venv is rebuilt when the requirements change (their hash is kept beside it).
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$req" | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q --disable-pip-version-check -r "$req"
  echo "$want" > "$stamp"
fi
# The rerun CLI asks about analytics on first start; answer once, never wait on stdin.
timeout 120 "$venv/bin/rerun" analytics disable </dev/null >/dev/null 2>&1 || true

deb_version() { dpkg-query -W -f='${Version}' "$1" 2>/dev/null || echo "missing"; }
py_versions="$("$venv/bin/python" - <<'PY'
from importlib.metadata import version
names = ["rerun-sdk", "mcap", "protobuf", "opencv-python-headless", "evo", "onnxruntime", "numpy", "websocket-client", "rosbags"]
print(", ".join(f"{n} {version(n)}" for n in names))
PY
)"
echo "peers ($venv): $py_versions"
echo "peers (Debian): OctoMap $(deb_version liboctomap-dev), octomap-tools $(deb_version octomap-tools), g++ $(deb_version g++), Mesa lavapipe $(deb_version mesa-vulkan-drivers), Chromium $(deb_version chromium)"

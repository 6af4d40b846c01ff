#!/usr/bin/env bash
# What attaching `dynaflow top` costs a run: the default graph in lockstep, recording off,
# alone and with `top --json --follow` polling every 0.2 s (five times the default rate), best
# of ROUNDS alternating; the engine's own wall time (`wall_s` of the summary, without process
# start-up) and the per-port digests of both (attaching must change none).
#   benches/watch/attach.sh [FRAMES=300] [ROUNDS=3]
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${DYNAFLOW:-${CARGO_TARGET_DIR:-target}/release/dynaflow}"
frames="${1:-300}"
rounds="${2:-3}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
wall() { python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["wall_s"])' "$1/default.summary.json"; }
digests() { python3 -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))["digests"], sort_keys=True))' "$1/default.summary.json"; }
best_off=inf best_on=inf
for r in $(seq "$rounds"); do
  "$bin" run graphs/default.yaml --record none --digest --no-progress -q --frames "$frames" --out "$tmp/off$r" >/dev/null
  "$bin" run graphs/default.yaml --record none --digest --no-progress -q --frames "$frames" --out "$tmp/on$r" >/dev/null &
  run=$!
  "$bin" top "$tmp/on$r" --json --follow --interval 0.2 --wait 60 >"$tmp/looks$r.jsonl"
  wait "$run"
  off=$(wall "$tmp/off$r") on=$(wall "$tmp/on$r")
  looks=$(grep -c '"state"' "$tmp/looks$r.jsonl" || true)
  same=$([ "$(digests "$tmp/off$r")" = "$(digests "$tmp/on$r")" ] && echo yes || echo NO)
  echo "round $r: alone $off s, watched $on s ($looks looks), digests equal: $same"
  best_off=$(python3 -c "print(min(float('$best_off'), $off))")
  best_on=$(python3 -c "print(min(float('$best_on'), $on))")
done
python3 -c "print(f'default graph, {$frames} frames, best of {$rounds}: alone {$best_off:.3f} s, with top attached {$best_on:.3f} s: {$best_on/$best_off:.3f}x')"

#!/usr/bin/env bash
# Per-port content digests of every shipped graph and variant, for comparing two builds
# ("identical digests before and after"):
#   scripts/digests.sh BINARY OUTDIR [FRAMES]     # one build's digests, OUTDIR/<graph>[-<variant>].digests
#   scripts/digests.sh --compare DIR_A DIR_B      # which ports differ, by port name
# Uses only bash, awk and python3's standard library.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--compare" ]; then
  python3 - "$2" "$3" <<'PY'
import json, glob, os, sys, collections
a, b = sys.argv[1], sys.argv[2]
changed, same, total = collections.Counter(), 0, 0
for f in sorted(glob.glob(os.path.join(a, "*.digests"))):
    A = json.load(open(f)); B = json.load(open(os.path.join(b, os.path.basename(f))))
    if A is None or B is None:
        print(os.path.basename(f), "missing digests"); continue
    for k in sorted(set(A) | set(B)):
        total += 1
        if A.get(k) == B.get(k): same += 1
        else: changed[k.split("/")[-1]] += 1
print(f"ports compared {total}, identical {same}, differing by port name {dict(changed)}")
PY
  exit 0
fi
bin=$1 out=$2 frames=${3:-40}
mkdir -p "$out"
for g in graphs/*.yaml; do
  name=$(basename "$g" .yaml)
  variants=$(awk '/^variants:/ {v=1; next} v && /^[^ #]/ {v=0} v && /^  [A-Za-z0-9_+-]+:/ {sub(/^  /, ""); sub(/:.*/, ""); print}' "$g")
  for v in "" $variants; do
    tag=$name${v:+-$v}
    args=(); [ -n "$v" ] && args=(--variant "$v")
    "$bin" run "$g" "${args[@]}" --frames "$frames" --record none --digest --out "$out/run-$tag" -q >"$out/$tag.log" 2>&1 || echo "$tag: exit $?"
    python3 -c 'import json,sys,glob; f=glob.glob(sys.argv[1]+"/*.summary.json"); d=json.load(open(f[0])) if f else {}; json.dump(d.get("digests"), open(sys.argv[2],"w"), indent=1, sort_keys=True)' "$out/run-$tag" "$out/$tag.digests"
  done
done

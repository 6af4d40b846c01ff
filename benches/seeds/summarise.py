"""Mean, min and max ATE RMSE (cm) per graph and variant over the seeds' bench.csv files,
with the improvement over orb_baseline on the same seed and each scored rule's precision and
recall against the generator's masks (mean over the seeds); a markdown table on stdout."""
import csv
import glob
import statistics
import sys
from collections import defaultdict

out, seeds = sys.argv[1], sys.argv[2:]
ate = defaultdict(dict)
labels = defaultdict(lambda: defaultdict(list))
for s in seeds:
    for path in sorted(glob.glob(f"{out}/seed-{s}/**/bench.csv", recursive=True)):
        with open(path) as f:
            for row in csv.DictReader(f):
                key = (row["graph"], row["variant"] + (" (oracle)" if row.get("oracle") == "true" else ""))
                ate[key][s] = float(row["ate_rmse_m"]) * 100 if row["status"] == "ok" else float("nan")
                # "node P/R node P/R ..." (dynaflow bench's labels_precision_recall column)
                words = (row.get("labels_precision_recall") or "").split()
                for node, pr in zip(words[::2], words[1::2]):
                    labels[key][node].append([float(v) for v in pr.split("/")])
base = ate[("orb_baseline", "base")]


def scores(key):
    per = labels.get(key, {})
    return "; ".join(f"{n} {statistics.mean(p for p, _ in v):.2f}/{statistics.mean(r for _, r in v):.2f}"
                     for n, v in per.items()) or "-"


print(f"| graph | variant | ATE rmse mean (cm) | min | max | per seed ({', '.join(seeds)}) | vs orb_baseline, mean | labels precision / recall, mean |")
print("|---|---|---|---|---|---|---|---|")
for (g, v), by_seed in ate.items():
    vals = [by_seed[s] for s in seeds if s in by_seed]
    gain = [100 * (base[s] - by_seed[s]) / base[s] for s in seeds if s in by_seed and s in base]
    cut = "-" if g == "orb_baseline" else f"{statistics.mean(gain):+.0f} % ({min(gain):+.0f} to {max(gain):+.0f})"
    print(f"| {g} | {v} | {statistics.mean(vals):.2f} | {min(vals):.2f} | {max(vals):.2f} | "
          f"{' / '.join(f'{x:.2f}' for x in vals)} | {cut} | {scores((g, v))} |")

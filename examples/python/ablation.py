"""An ablation from Python, notebook style: the ORB-SLAM2 baseline without culling against
MG-SLAM's culling (semantic OR geometric, as the paper) and a stricter variant (semantic AND
geometric), on the same synthetic walking sequence; the ATE of each as a bar chart.

    pip install .            # the dynaflow package, from the repository root
    pip install matplotlib
    python examples/python/ablation.py --frames 300 --out out/ablation

Writes <out>/ablation.png and prints one line of JSON (each row's ATE, from the run's own
summary) after the table.
"""

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files, no display
import matplotlib.pyplot as plt

import dynaflow

REPO = Path(__file__).resolve().parents[2]

# %% The rows: a label, the graph, and what changes.
ROWS = [
    ("ORB-SLAM2 (no culling)", "graphs/orb_baseline.yaml", {}),
    ("MG-SLAM: S or G", "graphs/mg_slam.yaml", {}),
    ("MG-SLAM: S and G", "graphs/mg_slam.yaml", {"combined.mode": "and"}),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--out", default="out/ablation")
    args = ap.parse_args()
    out = Path(args.out)

    # %% Run each row (no recordings: the summary holds the ATE).
    results = []
    for i, (label, graph, overrides) in enumerate(ROWS):
        s = dynaflow.run(REPO / graph, out=out / f"row{i}", frames=args.frames, set=overrides)
        results.append({"label": label, "ate_rmse": s.ate["rmse"], "summary": str(s.path)})

    # %% The table and the chart.
    for r in results:
        print(f"{r['label']:<26} ATE {r['ate_rmse'] * 100:7.2f} cm")
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=100)
    ax.barh([r["label"] for r in results], [r["ate_rmse"] * 100 for r in results], color=["#888", "#2a7", "#27a"])
    ax.set_xlabel("ATE RMSE (cm)")
    ax.set_title(f"walking scene, {args.frames} frames")
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(out / "ablation.png")
    print(json.dumps({"rows": results, "plot": str(out / "ablation.png")}))


if __name__ == "__main__":
    main()

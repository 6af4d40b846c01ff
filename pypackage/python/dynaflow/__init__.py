"""dynaflow from Python: run graphs, read their recordings, evaluate trajectories.

    import dynaflow
    summary = dynaflow.run("graphs/mg_slam.yaml", variant="stereo", out="out", frames=100)
    print(summary.ate["rmse"])
    rec = dynaflow.Recording("out/mg_slam-stereo.mcap")
    est = rec.poses("/track/pose")            # N x 8: stamp tx ty tz qx qy qz qw (TUM)
    gt = rec.poses("/camera/gt_pose")
    print(dynaflow.eval(gt, est)["ate"]["rmse"])

The work happens in dynaflow's Rust libraries (the `dynaflow._native` extension): `run` is
`dynaflow run` in this process, `Recording` reads MCAP recordings with dynaflow's own reader,
`eval` is `dynaflow eval` (evo's ATE and RPE). Python operators (`op: python`) run inside
this interpreter.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _native

__all__ = ["run", "Summary", "RunError", "Recording", "eval", "version"]

PathLike = Union[str, "os.PathLike[str]"]

#: Exit statuses of a run (the CLI's).
EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130


def version() -> str:
    """The dynaflow version this package was built from."""
    return _native.version()


class RunError(RuntimeError):
    """A run that did not complete: `status` is the CLI's exit status (1 failed, 2 bad input,
    130 interrupted); the messages went to standard error. `summary` is the run's summary when
    it wrote one (a failed or interrupted run does)."""

    def __init__(self, status: int, message: str, summary: Optional["Summary"] = None):
        super().__init__(message)
        self.status = status
        self.summary = summary


class Summary:
    """A run's summary (`<out>/<stem>.summary.json`), the type `dynaflow run` writes.

    Attributes: `run` (dict: graph, variant, seed, status, frames, wall_s, nodes (per-node
    timings), edges, dropped, recorders, failures), `status` and `frames` (from it), `ate`
    (the first tracker's ATE: `rmse`, `mean`, `median`, `std`, `max`, `align`, `pairs`,
    `scale`, `node`; None without ground truth), `trackers` (every tracker's ATE by node),
    `digests` (per-port content digests with `digest=True`), `path` (the file), `raw` (the
    whole document).
    """

    def __init__(self, path: PathLike):
        self.path = Path(path)
        with open(self.path, encoding="utf-8") as f:
            self.raw: dict = json.load(f)
        self.run: dict = {k: v for k, v in self.raw.items() if k not in ("ate", "trackers", "digests")}
        self.status: Optional[str] = self.run.get("status")
        self.frames: Optional[int] = self.run.get("frames")
        self.ate: Optional[dict] = self.raw.get("ate")
        self.trackers: dict = self.raw.get("trackers", {})
        self.digests: Optional[dict] = self.raw.get("digests")

    def __repr__(self) -> str:
        ate = f", ate rmse {self.ate['rmse']:.4f} m" if self.ate else ""
        return f"Summary({self.path}, {self.status}, {self.frames} frames{ate})"


def _flag(args: list, name: str, value: Any) -> None:
    if value is None or value is False:
        return
    if value is True:
        args.append(name)
    else:
        args += [name, str(value)]


def run(
    graph: PathLike,
    *,
    variant: Optional[str] = None,
    input: Optional[PathLike] = None,
    set: Optional[Mapping[str, Any]] = None,
    out: PathLike = "out",
    frames: Optional[int] = None,
    seed: Optional[int] = None,
    record: str = "none",
    digest: bool = False,
    intrinsics: Optional[str] = None,
    topics: Optional[str] = None,
) -> Summary:
    """Run a graph as `dynaflow run` does, in this process, and return its summary.

    `set` maps `node.param` to a value (each becomes `--set node.param=value`: a bool is
    written `true`/`false`); `record` is `none` (the default here), `rrd`, `mcap`, `ros2`,
    `jsonl` or a comma-separated list. Raises `RunError` when the run does not complete (its
    messages are on standard error), with the summary when the run wrote one.
    """
    args = ["dynaflow", "run", "--no-progress", "--out", os.fspath(out), "--record", record]
    _flag(args, "--variant", variant)
    _flag(args, "--input", os.fspath(input) if input is not None else None)
    _flag(args, "--frames", frames)
    _flag(args, "--seed", seed)
    _flag(args, "--digest", digest)
    _flag(args, "--intrinsics", intrinsics)
    _flag(args, "--topics", topics)
    for key, value in (set or {}).items():
        text = ("true" if value else "false") if isinstance(value, bool) else str(value)
        args += ["--set", f"{key}={text}"]
    args.append(os.fspath(graph))
    started = time.time()
    status = _native.cli(args)
    summary = _newest_summary(Path(out), started)
    if status != EXIT_OK:
        raise RunError(status, f"dynaflow run {os.fspath(graph)} ended with status {status} (see the messages above)", summary)
    if summary is None:
        raise RunError(status, f"the run wrote no summary under {os.fspath(out)}")
    return summary


def _newest_summary(out: Path, since: float) -> Optional[Summary]:
    found = [p for p in out.glob("*.summary.json") if p.stat().st_mtime >= since - 1.0]
    if not found:
        return None
    return Summary(max(found, key=lambda p: p.stat().st_mtime))


class Recording:
    """A dynaflow MCAP recording read back (a run with `record="mcap"` writes
    `<out>/<stem>.mcap`): every port is a topic `/<node>/<port>` whose messages carry
    dynaflow's own payload.

    `topics` maps topic to port type; `provenance` is the run's metadata (graph, variant,
    seed, version, ...); `truncated` says the file ended early (a killed run: what came before
    the cut is read).
    """

    def __init__(self, path: PathLike):
        self.path = Path(path)
        doc = json.loads(_native.read_recording(os.fspath(path)))
        self.provenance: dict = doc["metadata"]
        self.truncated: bool = doc["truncated"]
        self._topics: dict = doc["topics"]
        self.topics: dict = {name: t["type"] for name, t in self._topics.items()}

    def _topic(self, topic: str, kind: Optional[str] = None) -> dict:
        if topic not in self._topics:
            raise KeyError(f"{self.path} has no topic {topic!r} (topics: {', '.join(sorted(self._topics))})")
        t = self._topics[topic]
        if kind is not None and t["type"] != kind:
            raise TypeError(f"{topic} carries {t['type']!r} messages, not {kind!r}")
        return t

    def messages(self, topic: str) -> list:
        """The topic's messages in frame order, each a dict: `seq`, `stamp`, `frame_id` and
        `data` (the payload as dynaflow records it)."""
        frames = self._topic(topic)["frames"]
        return [frames[k] for k in sorted(frames, key=int)]

    def poses(self, topic: str) -> np.ndarray:
        """A `pose` topic as an N x 8 array, one row per frame: stamp, tx, ty, tz, qx, qy, qz,
        qw (a TUM trajectory file's columns)."""
        rows = [[m["stamp"], *m["data"]["t"], *m["data"]["q"]] for m in self.messages(self._check(topic, "pose"))]
        return np.asarray(rows, dtype=np.float64).reshape(-1, 8)

    def labels(self, topic: str) -> list:
        """A `point_labels` topic: per frame a dict of arrays (`index`, `dynamic`, `reason`,
        `score`) with `seq` and `stamp`."""
        out = []
        for m in self.messages(self._check(topic, "point_labels")):
            d = m["data"]
            out.append(
                {
                    "seq": m["seq"],
                    "stamp": m["stamp"],
                    "index": np.asarray(d.get("index", []), dtype=np.uint32),
                    "dynamic": np.asarray(d.get("dynamic", []), dtype=bool),
                    "reason": np.asarray(d.get("reason", []), dtype=object),
                    "score": np.asarray(d.get("score", []), dtype=np.float32),
                }
            )
        return out

    def scalars(self, topic: str) -> dict:
        """A `scalars` topic: `seq` and `stamp` arrays and one float array per name (NaN on
        frames without it)."""
        msgs = self.messages(self._check(topic, "scalars"))
        names: list = []
        for m in msgs:
            names += [k for k in m["data"] if k not in names]
        out = {"seq": np.asarray([m["seq"] for m in msgs], dtype=np.uint64), "stamp": np.asarray([m["stamp"] for m in msgs])}
        for n in names:
            out[n] = np.asarray([m["data"].get(n, np.nan) for m in msgs], dtype=np.float64)
        return out

    def _check(self, topic: str, kind: str) -> str:
        self._topic(topic, kind)
        return topic

    def __repr__(self) -> str:
        return f"Recording({self.path}, {len(self.topics)} topics{', truncated' if self.truncated else ''})"


TrajectoryLike = Union[PathLike, np.ndarray, Sequence[Sequence[float]]]


def _trajectory(t: TrajectoryLike) -> Union[str, list]:
    if isinstance(t, (str, os.PathLike)):
        return os.fspath(t)
    a = np.asarray(t, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 8:
        raise ValueError(f"a trajectory is N x 8 (stamp tx ty tz qx qy qz qw), got shape {a.shape}")
    return a.tolist()


def eval(
    groundtruth: TrajectoryLike,
    estimate: TrajectoryLike,
    *,
    align: str = "se3",
    max_diff: float = 0.01,
    rpe_delta: int = 1,
) -> dict:
    """ATE and RPE of `estimate` against `groundtruth`, as `dynaflow eval --json` (evo's
    definitions): each a TUM file path (or a EuRoC ground-truth CSV) or an N x 8 array.
    `align` is `se3`, `sim3` or `none`; poses are associated within `max_diff` seconds; the
    RPE spans `rpe_delta` frames. Returns the report as a dict (`ate`, `rpe_translation`,
    `rpe_rotation_deg` (each with `rmse`, `mean`, `median`, `std`, `min`, `max`, `count`),
    `matched`, `poses`, `align`, `scale`)."""
    if align not in ("se3", "sim3", "none"):
        raise ValueError(f"align must be se3, sim3 or none, not {align!r}")
    return json.loads(_native.evaluate(_trajectory(groundtruth), _trajectory(estimate), align, float(max_diff), int(rpe_delta)))

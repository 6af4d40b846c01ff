"""dynaflow's Rust side (the `dynaflow._native` extension module); use the `dynaflow` package."""

from typing import List, Sequence, Union

Trajectory = Union[str, Sequence[Sequence[float]]]

def cli(args: List[str]) -> int:
    """The `dynaflow` command line with `args` (the first is the program name), in this process; its exit status."""

def read_recording(path: str) -> str:
    """An MCAP recording as JSON: `metadata`, `truncated`, `topics` (name to `type`, `schema`, `frames`)."""

def evaluate(gt: Trajectory, est: Trajectory, align: str, max_diff: float, rpe_delta: int) -> str:
    """`dynaflow eval --json`'s report as JSON."""

def version() -> str:
    """The version of dynaflow this module was built from."""

"""`trunkslam reproduce`: run experiments from the registry and write manifest.json."""

from __future__ import annotations

import importlib.metadata
import logging
import platform
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from experiments.export import dumps_json, write_atomic
from experiments.runner import EXPERIMENTS, RunContext, get_experiment

__all__ = ["run_experiments", "git_commit", "versions"]

log = logging.getLogger(__name__)
REPO = Path(__file__).resolve().parent.parent


def git_commit() -> str | None:
    """The repository's HEAD commit, with '+dirty' when the tree has changes; None outside git."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+dirty" if dirty else "")


def versions() -> dict[str, str]:
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for pkg in ("trunkslam", "numpy", "scipy", "numba", "gtsam", "rerun-sdk", "matplotlib"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def run_experiments(
    names: list[str],
    out_dir: Path,
    quick: bool = False,
    seed: int = 0,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[Path]:
    """Run the named experiments (all when empty) into out_dir; returns the files written."""
    names = list(names) or list(EXPERIMENTS)
    funcs = {}
    for n in names:  # unknown names fail before any work
        fn = get_experiment(n)
        if fn not in funcs.values():  # table1 and table2 share one Monte Carlo
            funcs[n] = fn
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ctx = RunContext(out_dir=out_dir, quick=quick, seed=seed)
    if progress is not None:
        ctx.progress = progress
    timings = {}
    for name, fn in funcs.items():
        t0 = time.perf_counter()
        ctx.config.setdefault(name, {})
        fn(ctx)
        timings[name] = round(time.perf_counter() - t0, 2)
        log.info("%s done in %.1f s", name, timings[name])
    manifest = {
        "experiments": names,
        "quick": quick,
        "seed": seed,
        "git_commit": git_commit(),
        "versions": versions(),
        "config": ctx.config,
        "seconds": timings,
        "outputs": sorted(str(p.relative_to(out_dir)) for p in set(ctx.outputs)),
    }
    path = write_atomic(out_dir / "manifest.json", dumps_json(manifest))
    return sorted(set(ctx.outputs)) + [path]

"""`trunkslam reproduce`: run experiments from the registry and write manifest.json."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

from experiments.io.provenance import git_commit, versions
from experiments.io.writers import dumps_json, write_atomic
from experiments.paper.runner import DEFAULT_EXPERIMENTS, RunContext, get_experiment

__all__ = ["run_experiments"]

log = logging.getLogger(__name__)


def run_experiments(
    names: list[str],
    out_dir: Path,
    quick: bool = False,
    seed: int = 0,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[Path]:
    """Run the named experiments (all when empty) into out_dir; returns the files written."""
    names = list(dict.fromkeys(names)) or list(DEFAULT_EXPERIMENTS)
    groups: dict[Callable, list[str]] = {}  # names that share a function are one run
    for n in names:  # unknown names fail before any work
        groups.setdefault(get_experiment(n), []).append(n)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ctx = RunContext(out_dir=out_dir, quick=quick, seed=seed)
    if progress is not None:
        ctx.progress = progress
    timings = {}
    step = ctx.progress
    for i, (fn, group) in enumerate(groups.items()):
        step("experiments", i, len(groups))
        log.info("running %s", " ".join(group))
        t0 = time.perf_counter()
        before = set(ctx.config)
        fn(ctx)
        name = " ".join(group)
        timings[name] = round(time.perf_counter() - t0, 2)
        # the resolved parameters, under every name the run stands for
        written = [k for k in ctx.config if k not in before and ctx.config[k]]
        shared = ctx.config[written[0]] if written else {}
        for n in group:
            ctx.config[n] = ctx.config.get(n) or shared
        log.info("%s done in %.1f s", name, timings[name])
        step("experiments", i + 1, len(groups))
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

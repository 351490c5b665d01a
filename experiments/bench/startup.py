"""`trunkslam bench startup`: how long the command line takes to answer before any work.

Three answers a new user meets first, each timed in a fresh process (nothing imported, nothing
cached in the process; the operating system's file cache warm after the first run): the preset
list (`trunkslam presets`), a command's help (`trunkslam slam --help`) and a refused input
(`trunkslam slam missing.npz`, exit code 1). Wall time and the CPU time of the process (user +
system), median of `repeats` runs; on a busy machine the CPU time is the fairer figure. The
target is under 0.5 s each on an idle core.
"""

from __future__ import annotations

import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from experiments.io.provenance import machine
from experiments.io.writers import markdown_table

__all__ = ["COMMANDS", "TARGET_S", "bench_startup", "format_table", "trunkslam_command"]

TARGET_S = 0.5
# (arguments, the exit code that answer has)
COMMANDS = ((["presets"], 0), (["slam", "--help"], 0), (["slam", "missing.npz"], 1))


def trunkslam_command() -> list[str]:
    """The `trunkslam` this Python installed (its console script), else `python -m`."""
    script = Path(sys.executable).parent / "trunkslam"
    if script.is_file():
        return [str(script)]
    found = shutil.which("trunkslam")
    return [found] if found else [sys.executable, "-m", "experiments.cli"]


def _timed(argv: list[str], cwd: Path, code: int) -> tuple[float, float]:
    """(wall s, CPU s) of one run of `argv`; a `RuntimeError` if it answers otherwise."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, env=_env(), check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != code:
        raise RuntimeError(f"{argv}: exit {res.returncode}, expected {code}\n{res.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("COLUMNS", None)
    return env | {"TERM": "dumb"}


def bench_startup(repeats: int = 5, progress: Callable | None = None) -> list[dict]:
    """One row per command of `COMMANDS`: median wall and CPU seconds over `repeats` fresh
    processes (after one untimed run that warms the file cache)."""
    exe = trunkslam_command()
    rows = []
    with tempfile.TemporaryDirectory(prefix="trunkslam_startup_") as tmp:
        for k, (args, code) in enumerate(COMMANDS):
            _timed([*exe, *args], Path(tmp), code)  # warm-up, not counted
            times = [_timed([*exe, *args], Path(tmp), code) for _ in range(repeats)]
            rows.append(
                {
                    "command": "trunkslam " + " ".join(args),
                    "wall_s": statistics.median(t[0] for t in times),
                    "cpu_s": statistics.median(t[1] for t in times),
                    "runs": repeats,
                }
            )
            if progress is not None:
                progress("startup", k + 1, len(COMMANDS))
    return rows


def format_table(rows: list[dict]) -> str:
    """Markdown table of `bench_startup` rows, with the machine and the target."""
    body = markdown_table(
        ["command", "median wall s", "median CPU s", "runs", f"CPU under {TARGET_S} s"],
        [
            [
                f"`{r['command']}`",
                round(r["wall_s"], 3),
                round(r["cpu_s"], 3),
                r["runs"],
                "yes" if r["cpu_s"] < TARGET_S else "no",
            ]
            for r in rows
        ],
    )
    return f"Start-up time, fresh processes ({machine()})\n\n{body}"

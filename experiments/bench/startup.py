"""`trunkslam bench startup`: how long the command line takes to answer before any work.

Three answers a new user meets first, each timed in a fresh process (nothing imported, nothing
cached in the process; the operating system's file cache warm after the first run): the preset
list (`trunkslam presets`), a command's help (`trunkslam slam --help`) and a refused input
(`trunkslam slam missing.npz`, exit code 1). Wall time and the CPU time of the process (user +
system), median of `repeats` runs; on a busy machine the CPU time is the fairer figure. The
target is under 0.5 s each on an idle core.

And a first run's first line: `trunkslam slam` on a small simulated sequence with an empty
numba cache (`NUMBA_CACHE_DIR`, as after an install), timed until its first line (stdout or
stderr) and then stopped, as the compile it announces would take minutes. Target: within 2 s.
"""

from __future__ import annotations

import os
import resource
import selectors
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

__all__ = [
    "COMMANDS",
    "FIRST_LINE",
    "FIRST_LINE_TARGET_S",
    "TARGET_S",
    "bench_startup",
    "first_line",
    "format_table",
    "trunkslam_command",
]

TARGET_S = 0.5
# (arguments, the exit code that answer has)
COMMANDS = ((["presets"], 0), (["slam", "--help"], 0), (["slam", "missing.npz"], 1))
FIRST_LINE = "trunkslam slam run.npz, empty numba cache: first line"
FIRST_LINE_TARGET_S = 2.0
FIRST_LINE_TIMEOUT_S = 600.0  # a run that says nothing for this long ends the benchmark


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


def first_line(argv: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s) from the start of `argv` to its first line on stdout or stderr, then
    stopped; a `RuntimeError` if it ends or stays silent for `FIRST_LINE_TIMEOUT_S` first."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        with selectors.DefaultSelector() as sel:
            sel.register(proc.stdout, selectors.EVENT_READ)
            sel.register(proc.stderr, selectors.EVENT_READ)
            ready = sel.select(FIRST_LINE_TIMEOUT_S)
            line = ready[0][0].fileobj.readline() if ready else b""
            wall = time.perf_counter() - t0
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    if not line.strip():
        raise RuntimeError(f"{argv}: no line (exit {proc.returncode})")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _first_lines(exe: list[str], tmp: Path, repeats: int) -> list[tuple[float, float]]:
    """`first_line` of `trunkslam slam` on a 5-scan simulated drive, each run with its own
    empty numba cache."""
    run = tmp / "run.npz"
    args = ["simulate-drive", "tree_park", "--scans", "5", "--seed", "0", "--out", str(run)]
    _timed([*exe, *args], tmp, 0)
    times = []
    for k in range(repeats):
        cache = tmp / f"numba_cache_{k}"
        env = _env() | {"NUMBA_CACHE_DIR": str(cache)}
        times.append(first_line([*exe, "slam", str(run), "--out", str(tmp / "out")], tmp, env))
        shutil.rmtree(cache, ignore_errors=True)
    return times


def _row(command: str, times: list[tuple[float, float]], target_s: float) -> dict:
    return {
        "command": command,
        "wall_s": statistics.median(t[0] for t in times),
        "cpu_s": statistics.median(t[1] for t in times),
        "runs": len(times),
        "target_s": target_s,
    }


def bench_startup(repeats: int = 5, progress: Callable | None = None) -> list[dict]:
    """One row per command of `COMMANDS`: median wall and CPU seconds over `repeats` fresh
    processes (after one untimed run that warms the file cache); then the `FIRST_LINE` row."""
    exe = trunkslam_command()
    rows = []
    with tempfile.TemporaryDirectory(prefix="trunkslam_startup_") as tmp:
        for k, (args, code) in enumerate(COMMANDS):
            _timed([*exe, *args], Path(tmp), code)  # warm-up, not counted
            times = [_timed([*exe, *args], Path(tmp), code) for _ in range(repeats)]
            rows.append(_row("trunkslam " + " ".join(args), times, TARGET_S))
            if progress is not None:
                progress("startup", k + 1, len(COMMANDS) + 1)
        times = _first_lines(exe, Path(tmp), repeats)
        rows.append(_row(FIRST_LINE, times, FIRST_LINE_TARGET_S))
        if progress is not None:
            progress("startup", len(COMMANDS) + 1, len(COMMANDS) + 1)
    return rows


def format_table(rows: list[dict]) -> str:
    """Markdown table of `bench_startup` rows, with the machine and the target."""
    body = markdown_table(
        ["command", "median wall s", "median CPU s", "runs", "target CPU s", "met"],
        [
            [
                f"`{r['command']}`",
                round(r["wall_s"], 3),
                round(r["cpu_s"], 3),
                r["runs"],
                r.get("target_s", TARGET_S),
                "yes" if r["cpu_s"] < r.get("target_s", TARGET_S) else "no",
            ]
            for r in rows
        ],
    )
    return f"Start-up time, fresh processes ({machine()})\n\n{body}"

"""`trunkslam bench cold`: what a fresh clone costs, against the same commands run again.

The checkout's committed HEAD is cloned into a temporary folder and installed there (`make
install`: its own .venv, so every numba kernel is keyed to the clone's paths and no cache of
this checkout serves it). Then each command runs twice: cold (numba's caches and pytest's cache
removed first, as in a fresh clone) and warm (right after, every cache in place). For each run:
the wall seconds and the CPU seconds of every process it started (`RUSAGE_CHILDREN`), and the
load average before it: the wall figures of a busy machine are not its idle ones, the CPU
figures nearly are.

Commands: `make check`, `make test`, `trunkslam reproduce --quick` (into a folder of the clone).
Uncommitted changes of the checkout are not in the clone: commit first. Each row names the
commit it measured, so that a table can keep rows of an earlier run (`keep_rows`: `make test`
takes half an hour, the others minutes) and still say what each row is.
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from experiments.errors import DataError
from experiments.io.provenance import machine
from experiments.io.writers import markdown_table

__all__ = [
    "COMMANDS",
    "bench_cold",
    "clear_caches",
    "cold_seconds",
    "format_cold",
    "keep_rows",
    "project_root",
    "read_cold",
    "table_machine",
]

COMMANDS: dict[str, list[str]] = {
    "check": ["make", "check"],
    "test": ["make", "test"],
    "quick": [".venv/bin/trunkslam", "reproduce", "--quick", "--out", "quick_results"],
}
TIMEOUT_S = 3 * 3600  # one command at most; a hung one ends the benchmark with a clear error


def project_root(start: Path | None = None) -> Path:
    """The git checkout holding `start` (default: this package's source)."""
    start = Path(start or Path(__file__).resolve().parent)
    try:
        out = subprocess.run(
            ["git", "-C", str(start), "rev-parse", "--show-toplevel"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        raise DataError(
            f"{start}: not in a git checkout, so there is nothing to clone ({exc})"
        ) from None
    return Path(out.stdout.strip())


def clear_caches(clone: Path) -> int:
    """Remove numba's cache files (every __pycache__'s .nbi/.nbc) and pytest's cache (where the
    test workers keep theirs) under `clone`; the count of files removed."""
    removed = 0
    for pattern in ("*.nbi", "*.nbc"):
        for f in clone.rglob(f"__pycache__/{pattern}"):
            if ".venv" not in f.parts:
                f.unlink()
                removed += 1
    if (clone / ".pytest_cache").is_dir():
        shutil.rmtree(clone / ".pytest_cache")
        removed += 1
    return removed


def _timed(args: list[str], cwd: Path, env: dict, log: Path) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the processes it started) of one command, its output to
    `log`; `DataError` with the log's tail when it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        with open(log, "w") as fh:
            done = subprocess.run(
                args, cwd=cwd, env=env, stdout=fh, stderr=subprocess.STDOUT, timeout=TIMEOUT_S
            )
    except (OSError, subprocess.SubprocessError) as exc:
        raise DataError(f"bench cold: `{' '.join(args)}` in {cwd}: {exc}") from None
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        tail = "".join(log.read_text(errors="replace").splitlines(keepends=True)[-15:])
        raise DataError(f"bench cold: `{' '.join(args)}` failed in {cwd}:\n{tail}")
    return wall, cpu


def bench_cold(
    names: list[str], repo: Path | None = None, progress: Callable | None = None
) -> list[dict]:
    """Rows {command, run (cold, warm), wall_s, cpu_s, load_1min} of each command of `names`
    (keys of COMMANDS) in a fresh clone of `repo`'s HEAD; the first row is the install."""
    unknown = [n for n in names if n not in COMMANDS]
    if unknown:
        raise DataError(f"bench cold: unknown command(s) {unknown} (known: {', '.join(COMMANDS)})")
    repo = project_root(repo)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "VIRTUAL_ENV"))}
    rows = []
    with tempfile.TemporaryDirectory(prefix="trunkslam-cold-") as tmp:
        clone = Path(tmp) / "trunkslam"
        try:
            subprocess.run(
                ["git", "clone", "--quiet", str(repo), str(clone)],
                check=True,
                timeout=600,
                capture_output=True,
                text=True,
            )
        except (OSError, subprocess.SubprocessError) as exc:
            why = getattr(exc, "stderr", None) or exc
            raise DataError(f"bench cold: cannot clone {repo}: {why}") from None
        commit = _short_head(clone)
        steps = [("install", "-", ["make", "install"])]
        for n in names:
            steps += [(n, "cold", COMMANDS[n]), (n, "warm", COMMANDS[n])]
        for i, (name, run, args) in enumerate(steps):
            if run == "cold":
                clear_caches(clone)
            shutil.rmtree(clone / "quick_results", ignore_errors=True)
            load = os.getloadavg()[0]
            wall, cpu = _timed(args, clone, env, Path(tmp) / f"{name}-{run}.log")
            command = " ".join(args).replace(".venv/bin/", "")
            rows.append(
                {
                    "command": command,
                    "run": run,
                    "commit": commit,
                    "wall_s": wall,
                    "cpu_s": cpu,
                    "load_1min": load,
                }
            )
            if progress is not None:
                progress("bench cold", i + 1, len(steps))
    return rows


def _short_head(clone: Path) -> str:
    """The short hash of `clone`'s HEAD."""
    try:
        out = subprocess.run(
            ["git", "-C", str(clone), "rev-parse", "--short=7", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        raise DataError(f"bench cold: cannot read the clone's commit: {exc}") from None
    return out.stdout.strip()


def format_cold(rows: list[dict]) -> str:
    """Markdown table of `bench_cold` rows, with the machine."""
    body = markdown_table(
        ["command", "run", "commit", "wall (s)", "CPU (s)", "load before (1 min)"],
        [
            [
                r["command"],
                r["run"],
                r.get("commit") or "-",
                f"{r['wall_s']:.0f}",
                f"{r['cpu_s']:.0f}",
                f"{r['load_1min']:.1f}",
            ]
            for r in rows
        ],
    )
    return (
        f"A fresh clone, cold and warm ({machine()})\n\n{body}\n"
        "Cold: numba's caches and pytest's removed first, as in a fresh clone; warm: the same "
        "command again at once. CPU: every process the command started. The install row is "
        "`make install` of the fresh clone (pip from its local cache). Commit: the clone's "
        "HEAD that row measured (rows of one command are from one run).\n"
    )


def read_cold(text: str) -> list[dict]:
    """The rows of a table `format_cold` wrote (wall and CPU seconds as printed, whole
    seconds); a table written before rows named their commit gives commit "-"."""
    rows = []
    for line in text.splitlines():
        if not line.startswith("| "):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5:
            cells.insert(2, "-")
        if len(cells) != 6 or cells[0] == "command" or set(cells[0]) <= set("-: "):
            continue
        try:
            wall, cpu, load = (float(c) for c in cells[3:])
        except ValueError:
            raise DataError(
                f"bench cold table: a row that is not a measurement: {line!r}"
            ) from None
        rows.append(
            {
                "command": cells[0],
                "run": cells[1],
                "commit": cells[2],
                "wall_s": wall,
                "cpu_s": cpu,
                "load_1min": load,
            }
        )
    return rows


def table_machine(text: str) -> str:
    """The machine a table of `format_cold` names in its first line; `DataError` without one."""
    first = text.splitlines()[0] if text else ""
    head = "A fresh clone, cold and warm ("
    if not (first.startswith(head) and first.endswith(")")):
        raise DataError("bench cold table: its first line does not name the machine")
    return first[len(head) : -1]


def keep_rows(rows: list[dict], kept: list[dict]) -> list[dict]:
    """`rows` (one benchmark's) with the rows of `kept` (an earlier table's, `read_cold`)
    whose command `rows` did not measure, each command's rows together, in `COMMANDS`' order
    (the install row first: the new one when `rows` has one)."""
    measured = {r["command"] for r in rows}
    order = ["make install"] + [" ".join(a).replace(".venv/bin/", "") for a in COMMANDS.values()]
    merged = rows + [r for r in kept if r["command"] not in measured]
    return sorted(
        merged, key=lambda r: order.index(r["command"]) if r["command"] in order else len(order)
    )


def cold_seconds(text: str, command: str, run: str) -> float:
    """The wall seconds of `command` (its start, e.g. "make check" or "trunkslam reproduce
    --quick") run `run` (cold, warm) in a table of `format_cold`: what the README and
    getting-started quote, checked against the table the benchmark wrote."""
    found = [
        r["wall_s"] for r in read_cold(text) if r["command"].startswith(command) and r["run"] == run
    ]
    if len(found) != 1:
        raise DataError(
            f"bench cold table: {len(found)} rows of {command!r} run {run!r} (one is needed)"
        )
    return found[0]

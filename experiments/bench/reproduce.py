"""`trunkslam bench reproduce`: wall time of `trunkslam reproduce` on 1 worker, on every core
(and on a Dask scheduler when given), and whether the tables came out the same.

Beside the wall time, each row gives the CPU time of this (the main) process
(`time.process_time`, all its threads; not the workers'): with workers, that is the work that
does not run on them (reducing, writing; waiting costs none), the part that does not shrink
with more cores.

Each run writes into its own temporary folder; the CSV tables of every run are compared cell
for cell with the first run's. The tables that hold wall times (columns `ms_per_scan`,
`seconds`, `ms_ihgr`, ...: association, association_loop, consistency, victoria_park, smoother,
association_optimality) differ by those columns only, so they are compared without them.
"""

from __future__ import annotations

import csv
import io
import os
import tempfile
import time
from pathlib import Path

from experiments.exec import make_executor
from experiments.io.provenance import machine
from experiments.io.writers import markdown_table
from experiments.paper.reproduce import run_experiments

__all__ = ["bench_reproduce", "format_table", "timeless_table"]


def timeless_table(path: Path) -> list[list[str]]:
    """A CSV table without its wall-time columns (names with 'ms' or 'seconds' as a word:
    `ms_per_scan`, `seconds`, `ms_ihgr`)."""
    rows = list(csv.reader(io.StringIO(path.read_text())))
    if not rows:
        return rows
    keep = [
        i
        for i, h in enumerate(rows[0])
        if not ({"ms", "seconds"} & set(h.replace("_", " ").split()) or h.startswith("ms_"))
    ]
    return [[r[i] for i in keep if i < len(r)] for r in rows]


def bench_reproduce(
    names: list[str] | None = None,
    quick: bool = False,
    workers: tuple = (1, None),
    dask: str | None = None,
    progress=None,
) -> list[dict]:
    """Run `reproduce` (default: every default experiment) once per entry of `workers` (None:
    every core) and once on `dask` when given; rows: executor, workers, seconds, this process's
    CPU seconds, speed-up over the first, tables identical to the first's."""
    runs = [(w, None) for w in workers] + ([(None, dask)] if dask else [])
    rows: list[dict] = []
    first: dict | None = None
    with tempfile.TemporaryDirectory(prefix="trunkslam-bench-") as tmp:
        for k, (w, d) in enumerate(runs):
            out = Path(tmp) / f"run{k}"
            with make_executor(w, d) as ex:
                t0, c0 = time.perf_counter(), time.process_time()
                run_experiments(list(names or []), out, quick=quick, executor=ex, progress=progress)
                seconds = time.perf_counter() - t0
                cpu = time.process_time() - c0
                described = ex.describe()
            tables = {p.name: timeless_table(p) for p in sorted(out.glob("*.csv"))}
            if first is None:
                first = tables
            same = sorted(n for n in tables if tables[n] == first.get(n))
            differ = sorted(set(tables) ^ set(first) | {n for n in tables if n not in same})
            rows.append(
                {
                    "executor": described["executor"],
                    "workers": described["workers"],
                    "seconds": round(seconds, 1),
                    "main-process CPU s": round(cpu, 1),
                    "speed-up": round(rows[0]["seconds"] / seconds, 2) if rows else 1.0,
                    "tables identical": f"{len(same)}/{len(tables)}",
                    "differ": ", ".join(differ) or "-",
                }
            )
    return rows


def format_table(rows: list[dict], what: str) -> str:
    header = list(rows[0])
    body = [[r[k] for k in header] for r in rows]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (
        f"trunkslam reproduce {what} ({machine()}; load average {load:.1f} at the end; tables "
        "compared without their wall-time columns)\n\n" + markdown_table(header, body)
    )

"""`trunkslam bench extract`: extractor throughput on the 2000 real Victoria Park scans."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError
from experiments.io.provenance import machine
from experiments.io.writers import markdown_table

__all__ = ["bench_extract", "format_extract"]


_COLD = """
import time, numpy as np
t0 = time.perf_counter()
from features import Scan, extract_features
t1 = time.perf_counter()
s = Scan(np.linspace(5.0, 6.0, 361), -np.pi / 2, np.pi / 360)
for m in ("paper", "bailey"):
    extract_features(s, m)
print(time.perf_counter() - t1)
"""


def cold_compile_seconds() -> float:
    """Numba compilation of every extractor kernel, measured in a fresh process with an empty
    cache folder (what the very first run on a machine pays; later runs load the cache)."""
    import os
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
        out = subprocess.run(
            [sys.executable, "-c", _COLD], env=env, capture_output=True, text=True, check=True
        )
    return float(out.stdout.strip().splitlines()[-1])


def bench_extract(
    repeats: int = 3,
    root: Path | None = None,
    methods=("paper", "geometric", "bailey"),
    progress: Callable[[str, int, int], None] | None = None,
) -> list[dict]:
    """Time each method over all scans, single thread, after a warm-up.

    The first call of a method (numba compilation, or loading its on-disk cache) is timed
    separately as `first_call_s`. Scans are built before timing; `scan_build_us` is the cost of
    constructing one `features.Scan` (validation and no-return masking), reported apart.
    progress(description, done, total) is called between the timed passes, never inside one.
    """
    step = progress or (lambda desc, done, total: None)
    desc = "extractor passes"
    total = len(methods) * repeats + 1  # and the cold compilation in a fresh process
    from experiments.io.victoria_park import load_victoria_park
    from features import extract_features

    if repeats < 1:
        raise ConfigError(f"repeats: must be >= 1, got {repeats}")
    seq = load_victoria_park(root)
    t0 = time.perf_counter()
    scans = [seq.scan(k) for k in range(seq.n_scans)]
    scan_build_us = (time.perf_counter() - t0) / len(scans) * 1e6
    rows = []
    for m in methods:
        t0 = time.perf_counter()
        extract_features(scans[0], m)
        first = time.perf_counter() - t0
        for s in scans[:50]:  # warm-up
            extract_features(s, m)
        per_pass = []
        n_circles = 0
        for _ in range(repeats):
            step(desc, len(rows) * repeats + len(per_pass), total)
            n_circles = 0
            t0 = time.perf_counter()
            for s in scans:
                n_circles += extract_features(s, m).n_circles
            per_pass.append(time.perf_counter() - t0)
        best = min(per_pass)
        rows.append(
            {
                "method": m,
                "scans": len(scans),
                "us_per_scan": best / len(scans) * 1e6,
                "scans_per_s": len(scans) / best,
                "median_us_per_scan": float(np.median(per_pass)) / len(scans) * 1e6,
                "first_call_s": first,
                "circles_per_scan": n_circles / len(scans),
                "scan_build_us": scan_build_us,
            }
        )
    step(desc, total - 1, total)
    compile_s = cold_compile_seconds()
    step(desc, total, total)
    for r in rows:
        r["cold_compile_s"] = compile_s
    return rows


def format_extract(rows: list[dict]) -> str:
    header = [
        "method",
        "scans/s",
        "us/scan (best)",
        "us/scan (median)",
        "first call (s)",
        "circles/scan",
    ]
    body = [
        [
            r["method"],
            round(r["scans_per_s"]),
            round(r["us_per_scan"], 1),
            round(r["median_us_per_scan"], 1),
            round(r["first_call_s"], 2),
            round(r["circles_per_scan"], 2),
        ]
        for r in rows
    ]
    note = (
        f"\nMachine: {machine()}. One thread, {rows[0]['scans']} Victoria Park scans of 361 beams"
        f" per pass, best and median of the passes. Building one Scan (validation) costs"
        f" {rows[0]['scan_build_us']:.1f} us more, not included. First call = numba compilation"
        " or loading its cache. Compiling all extractor kernels from an empty numba cache (first"
        f" run on a machine, fresh process): {rows[0]['cold_compile_s']:.1f} s.\n"
    )
    return markdown_table(header, body) + note

"""Probes behind issue 40's speed target (the full Victoria Park run, one core): the run's
outputs hashed, to show that a speed change leaves them identical to the bit, and an in-process
profile of the run.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/full_run_speed_probe.py \
        hash SEQUENCE.npz [--expect HASHES.json] [--save HASHES.json]
    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/full_run_speed_probe.py \
        profile SEQUENCE.npz [--top 40]

SEQUENCE.npz: `trunkslam convert victoria-park --full --out SEQUENCE.npz`. Both run the preset
`victoria_park_ute` with closure off and with `[closure] enabled = true`, at one BLAS/OpenMP
thread. "hash" writes each run's files as `trunkslam slam` does (`run_slam_file`) and prints
the SHA-256 of map.csv, trajectory.csv and of run_log.npz's arrays (names, dtypes, shapes and
bytes; the zip's own bytes carry the write time), and of every array of the `SlamLog` but its
timings; with --expect it exits 1 when one differs. "profile" runs both once untimed (numba
compiles or loads its kernels), then each once unprofiled (its CPU and wall seconds, and ms a
scan in each phase of the loop against the whole run's: what lies outside the four phases)
and once under cProfile: Python calls a step and the top functions by cumulative and by own
time with their calls a step (cProfile's own overhead inflates every Python call's time).
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import json
import pstats
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from experiments.io.config_file import load_slam_config
from experiments.io.sequence_file import load_sequence
from experiments.pipeline.slam import run_slam_file
from slam import run_slam

RUNS = {"closure off": False, "closure on": True}


def config(closure: bool):
    """The preset, with loop closure on or off."""
    return load_slam_config("victoria_park_ute").with_(**{"closure.enabled": closure})


def npz_digest(path: Path) -> str:
    """SHA-256 over an npz's arrays in name order: name, dtype, shape and bytes."""
    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as z:
        for name in sorted(z.files):
            a = np.ascontiguousarray(z[name])
            h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
            h.update(a.tobytes())
    return h.hexdigest()


def _feed(h, value) -> None:
    """Hash a value: arrays by dtype, shape and bytes (inside dicts, lists and tuples too: a
    repr would summarise a long array with "..."), anything else by its repr."""
    if isinstance(value, np.ndarray):
        h.update(f"{value.dtype.str}|{value.shape}|".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        h.update(f"dict{len(value)}|".encode())
        for k, v in value.items():
            h.update(f"{k!r}:".encode())
            _feed(h, v)
    elif isinstance(value, (list, tuple)):
        h.update(f"{type(value).__name__}{len(value)}|".encode())
        for v in value:
            _feed(h, v)
    else:
        h.update(repr(value).encode())


# fields of options added after a baseline, None when the option is off: left out then, so a
# baseline saved before the option still matches a run with it off
OFF_WHEN_NONE = ("joint_dropped",)


def log_digest(log) -> str:
    """SHA-256 over the `SlamLog`'s fields (its timings and config aside, and the fields of
    `OFF_WHEN_NONE` when None), field order."""
    h = hashlib.sha256()
    for name, value in vars(log).items():
        if name in ("timing_s", "config") or (name in OFF_WHEN_NONE and value is None):
            continue
        h.update(f"{name}|".encode())
        _feed(h, value)
    return h.hexdigest()


def run_hashes(seq_path: Path, closure: bool) -> dict:
    """The hashes of one run's files (`run_slam_file` into a temporary folder)."""
    with tempfile.TemporaryDirectory(prefix="trunkslam-speed-") as tmp:
        out = Path(tmp) / "run"
        run_slam_file(seq_path, config(closure), out)
        return {
            "map.csv": hashlib.sha256((out / "map.csv").read_bytes()).hexdigest(),
            "trajectory.csv": hashlib.sha256((out / "trajectory.csv").read_bytes()).hexdigest(),
            "run_log.npz arrays": npz_digest(out / "run_log.npz"),
        }


def hash_runs(seq_path: Path, expect: Path | None, save: Path | None) -> int:
    """Print the hashes of both runs; 1 when --expect's differ."""
    seq = load_sequence(seq_path)
    found = {}
    for name, closure in RUNS.items():
        found[name] = run_hashes(seq_path, closure)
        found[name]["SlamLog"] = log_digest(run_slam(seq, config(closure)))
        for k, v in found[name].items():
            print(f"{name:12s} {k:20s} {v}")
    if save is not None:
        save.write_text(json.dumps(found, indent=1) + "\n")
    if expect is None:
        return 0
    want = json.loads(expect.read_text())
    bad = [(n, k) for n in want for k in want[n] if found.get(n, {}).get(k) != want[n][k]]
    for n, k in bad:
        print(f"DIFFERS: {n} {k}")
    print("identical" if not bad else f"{len(bad)} differ")
    return 1 if bad else 0


def profile_runs(seq_path: Path, top: int) -> int:
    """Profile both runs after an untimed one; print CPU seconds, where the run's time goes
    against the loop's four timed phases (`phase_split`), and the top functions with their
    calls per step."""
    seq = load_sequence(seq_path)
    run_slam(seq, config(True))  # numba compiles or loads every kernel both runs use
    for name, closure in RUNS.items():
        cfg = config(closure)
        c0, t0 = time.process_time(), time.perf_counter()
        log = run_slam(seq, cfg)
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        prof = cProfile.Profile()
        prof.enable()
        run_slam(seq, cfg)
        prof.disable()
        stats = pstats.Stats(prof)
        steps = next(v[0] for k, v in stats.stats.items() if k[2] == "step" and "loop" in k[0])
        print(f"== {name}: {cpu:.2f} s CPU, {wall:.2f} s wall (unprofiled run)")
        print(phase_split(log, wall))
        print(
            f"profiled: {steps} steps (the run's scans, the GPS start's first pass, the "
            f"warm-up), {stats.total_calls / steps:.0f} Python calls a step"
        )
        for key in ("cumulative", "tottime"):
            print(per_step_table(stats, key, top, steps))
    return 0


def phase_split(log, wall: float) -> str:
    """The unprofiled run's wall seconds against its log's phase times (`SlamLog.timing_s`,
    the run's scans only): predict, associate, update and manage (the four phases; features
    is the measure step), the rest of the steps' timed total, and what lies outside them
    (the first pass and warm-up, the scan's record, log and bookkeeping, the final log)."""
    t = {k: float(np.sum(v)) for k, v in log.timing_s.items()}
    four = sum(t[k] for k in ("predict", "associate", "update", "manage"))
    n = log.n_scans
    parts = ", ".join(f"{k} {1e3 * t[k] / n:.3f}" for k in t)
    return (
        f"ms a scan over {n} scans: {parts}; the four phases {1e3 * four / n:.3f}, the whole "
        f"run {1e3 * wall / n:.3f} ({1e3 * (wall - four) / n:.3f} outside the four phases)"
    )


def per_step_table(stats: pstats.Stats, key: str, top: int, steps: int) -> str:
    """The top functions by `key` ("cumulative" or "tottime"): own and cumulative seconds,
    share of the profiled run, calls per step."""
    rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][3 if key == "cumulative" else 2])
    total = max(v[3] for v in stats.stats.values())
    out = [f"-- by {key}: own s, cumulative s, % of the run, calls a step, function"]
    for (path, line, fn), (_, ncalls, own, cum, _) in rows[:top]:
        where = f"{Path(path).parent.name}/{Path(path).name}:{line}" if line else path
        out.append(
            f"{own:7.2f} {cum:7.2f} {100 * (cum if key == 'cumulative' else own) / total:5.1f}% "
            f"{ncalls / steps:7.2f}  {fn} ({where})"
        )
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=("hash", "profile"))
    p.add_argument("sequence", type=Path)
    p.add_argument("--expect", type=Path, default=None)
    p.add_argument("--save", type=Path, default=None)
    p.add_argument("--top", type=int, default=40)
    a = p.parse_args(argv)
    with threadpool_limits(limits=1):
        if a.what == "hash":
            return hash_runs(a.sequence, a.expect, a.save)
        return profile_runs(a.sequence, a.top)


if __name__ == "__main__":
    sys.exit(main())

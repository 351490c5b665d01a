"""Compile (or load) the numba kernels of a whole run once, into numba's cache.

`python -m experiments.bench.warm` runs every extractor on a small scan (`local.warm_kernels`),
then a short simulated drive through the loop once per association method, with the single-scan
and the window associator, loop closure on (and its match, which so short a drive never
reaches), the smoother's input and the GPS scoring: the kernels and signatures a run and the
test suite use. `make test`, `make check` and CI run it before
the test workers start (tests/conftest.py), into a cache folder that each worker then copies
as its own: a fresh clone compiles each kernel once instead of once per worker.

Into an empty cache folder (`NUMBA_CACHE_DIR`, a fresh clone's) with `--jobs 2` (the default on
two cores or more), the compilation is split in two processes (`PARTS`: the extractors and the
GPS scoring; the loop's kernels on a drive of given features), each into a folder of its own:
numba's cache is not safe for two processes writing one kernel, so neither writes the other's
folder. Their kernels are then copied into the cache folder, each kernel's files from one part
(`merge_kernels`). When a part failed, or two parts compiled one kernel with different
signatures (the merge takes one part's), the whole warm-up runs once more in this process: it
loads the kernels and compiles what the parts left out; otherwise that pass would only load,
and is skipped (`merge_loses_nothing`). The parts share one kernel, the vehicle model's, with
the same signature (both drive a Cycab), so on two idle cores the cold warm-up takes the
longer part's time instead of the sum. A folder that holds kernels already is warmed
in this process alone, as before.

It prints one line when it starts and one with its time, so a cold first run is not a silence.
"""

from __future__ import annotations

import argparse
import io
import os
import pickle
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["PARTS", "merge_kernels", "merge_loses_nothing", "warm_every_kernel", "warm_in_parts"]

WARM_SCANS = 30  # enough for landmarks to join the map, be re-observed and the window to fill
AVENUE_TREES = 60  # the loop part's drive (`experiments.sim.landmarks.avenue`): 35 scans


def warm_every_kernel() -> float:
    """Run the kernels' warm-up (see the module doc); the seconds it took."""
    t0 = time.perf_counter()
    import numpy as np

    from experiments.eval.vouched import vouched_for_sequence
    from experiments.exec.local import warm_kernels
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import SlamConfig, run_slam

    warm_kernels()
    seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=WARM_SCANS))
    base = SlamConfig().with_(**{"closure.enabled": True})
    for method in ("ihgr", "jcbb", "nn", "ihgr-window"):
        run_slam(seq, base, association=method, warm_up=False)
    for features in ("geometric", "bailey"):
        run_slam(seq, base, features=features, warm_up=False)
    vouched_for_sequence(seq, base)
    _warm_unicycle()
    _warm_full_circle()
    _warm_matcher()
    _warm_closure_helpers()
    return time.perf_counter() - t0


def _warm_extractors() -> None:
    """Part "extractors": every extractor (a half and a full circle), the GPS scoring and the
    unicycle model: no kernel of the loop's."""
    import numpy as np

    from experiments.eval.vouched import vouched_for_sequence
    from experiments.exec.local import warm_kernels
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import SlamConfig

    warm_kernels()
    _warm_full_circle()
    seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=WARM_SCANS))
    vouched_for_sequence(seq, SlamConfig().with_(**{"closure.enabled": True}))
    _warm_unicycle()
    _warm_matcher()


def _warm_loop() -> None:
    """Part "loop": the loop with each associator and loop closure, on a drive of given
    features (an avenue's circle centres: no extractor kernel)."""
    import numpy as np

    from experiments.sim.landmarks import avenue
    from slam import SlamConfig, run_slam

    seq, feats = avenue(AVENUE_TREES, np.random.default_rng(0))
    base = SlamConfig().with_(**{"closure.enabled": True})
    for method in ("ihgr", "jcbb", "nn", "ihgr-window"):
        run_slam(seq, base, features=feats, association=method, warm_up=False)
    _warm_closure_helpers()


PARTS = {"extractors": _warm_extractors, "loop": _warm_loop}


def _warm_unicycle() -> None:
    """The unicycle model's kernel, which no Cycab drive uses (its tests compiled it in each
    test worker, about 3 s of CPU every run)."""
    import numpy as np

    from slam.motion import UnicycleMotion

    t = np.linspace(0.0, 1.0, 5)
    UnicycleMotion(t, np.ones(5), np.zeros(5)).integrate(np.zeros(3), 0.0, 1.0)


def _warm_matcher() -> None:
    """Loop closure's constellation match (`slam.closure.hypotheses`), which the warm-up's
    drives, too short to come back to a place, never reach: a cold `make check` compiled it in
    each test worker (about 11 s of CPU each; lab notebook, 2026-11-29). In the extractors'
    part, the shorter one."""
    import numpy as np

    from slam.closure import hypotheses

    old = np.random.default_rng(0).uniform(-20.0, 20.0, (12, 2))
    hypotheses(old[:6] + [1.0, -0.5], old, np.array([0.5, 3.0, 0.3, 15.0, 6.0]))


def _warm_closure_helpers() -> None:
    """Loop closure's dead-reckoned covariance, which only a return to a place reaches, with
    the run's array types (about 3 s of CPU in a test worker)."""
    import numpy as np

    from slam.closure import dead_reckoned_cov

    dead_reckoned_cov(np.zeros((4, 3)), np.zeros((4, 3, 3)), 0, 3)


def _warm_full_circle() -> None:
    """The extractor's kernels on a 360 deg scan (`simulate --back-to-back`, the README's first
    recipe), whose cyclic beams are another signature (about 18 s of CPU in the first test
    worker that extracts one)."""
    import numpy as np

    from experiments.sim import load_scene, sensor_preset, simulate_scan
    from features import METHODS, extract_features

    sensor = sensor_preset("pls200", back_to_back=True)
    scene, rng = load_scene("pillar_court"), np.random.default_rng(0)
    ranges, _ = simulate_scan(scene, (0.0, 0.0, 0.0), sensor, rng)
    scan = sensor.scan(ranges)
    for m in METHODS:
        extract_features(scan, m)


def merge_kernels(target: Path, parts: list[Path]) -> int:
    """Copy into the numba cache folder `target` each kernel that one of the folders `parts`
    holds and `target` does not: its data files, then its index, all from the first part that
    holds it (a kernel's files as one: an index never names another folder's data). The count
    of kernels copied."""
    copied = 0
    for part in parts:
        for index in sorted(part.rglob("*.nbi")):
            sub = index.parent.relative_to(part)
            if (target / sub / index.name).exists():
                continue
            (target / sub).mkdir(parents=True, exist_ok=True)
            for data in sorted(index.parent.glob(f"{index.name.removesuffix('.nbi')}.*.nbc")):
                _copy_atomic(data, target / sub / data.name)
            _copy_atomic(index, target / sub / index.name)
            copied += 1
    return copied


def _copy_atomic(src: Path, dst: Path) -> None:
    """Copy to a temporary name beside `dst`, then rename: a reader never sees half a file."""
    tmp = dst.with_name(f"{dst.name}.tmp-{os.getpid()}")
    shutil.copy2(src, tmp)
    os.replace(tmp, dst)


def warm_in_parts(target: Path) -> float:
    """Warm the empty cache folder `target` in two processes, then in this one (see the module
    doc); the seconds it took. A part that fails leaves its kernels to this process."""
    t0 = time.perf_counter()
    target.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=".warm-", dir=target.parent))
    try:
        runs = []
        for name in PARTS:
            env = {**os.environ, "NUMBA_CACHE_DIR": str(scratch / name)}
            args = [sys.executable, "-m", "experiments.bench.warm", "--part", name]
            runs.append(subprocess.Popen(args, env=env))
        done = [run.wait() == 0 for run in runs]
        merged = [scratch / n for n, ok in zip(PARTS, done) if ok]
        merge_kernels(target, merged)
        whole = all(done) and merge_loses_nothing(merged)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    if not whole:  # a part failed, or a signature of a kernel two parts hold was left out
        warm_every_kernel()
    return time.perf_counter() - t0


def merge_loses_nothing(parts: list[Path]) -> bool:
    """Whether `merge_kernels` of `parts` leaves out no signature: every kernel that more than
    one part holds has the same signatures in each (`_index_entries`), so the one part's files
    it takes hold them all. When it does, the last pass over the whole warm-up would only load
    (about 4 s of one core, after the parts: lab notebook, 2026-11-29)."""
    seen: dict[Path, object] = {}
    for part in parts:
        for index in part.rglob("*.nbi"):
            key, entries = index.relative_to(part), _index_entries(index)
            if seen.setdefault(key, entries) != entries:
                return False
    return True


def _index_entries(index: Path) -> object:
    """The (format, source stamp, signatures) of a numba cache index (numba.core.caching's
    `IndexDataCacheFile`: a pickled version, then a pickled (stamp, {key: data file})); its
    bytes when it cannot be read so (equal only to the same bytes)."""
    data = index.read_bytes()
    try:
        with io.BytesIO(data) as f:
            version = pickle.load(f)
            stamp, overloads = pickle.loads(f.read())
        return (version, stamp, frozenset(overloads))
    except Exception:  # not an index numba wrote: compared as bytes
        return data


def _holds_kernels(folder: Path) -> bool:
    return folder.is_dir() and next(folder.rglob("*.nbi"), None) is not None


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        prog="python -m experiments.bench.warm",
        description="Compile or load every numba kernel a run and the tests use.",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=2 if (os.cpu_count() or 1) >= 2 else 1,
        help="processes for a cold cache folder (NUMBA_CACHE_DIR, empty): 2 splits the "
        "compilation in two parts (default: %(default)s); 1 compiles in this process",
    )
    parser.add_argument("--part", choices=list(PARTS), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs: must be >= 1, got {args.jobs}")
    if args.part is not None:  # one part, into its own folder (warm_in_parts)
        PARTS[args.part]()
        return
    folder = os.environ.get("NUMBA_CACHE_DIR")
    split = args.jobs >= 2 and folder and not _holds_kernels(Path(folder))
    how = " in two processes" if split else ""
    print(f"numba kernels: compiling or loading{how} (a fresh clone: about a minute)", flush=True)
    seconds = warm_in_parts(Path(folder)) if split else warm_every_kernel()
    print(f"numba kernels: ready in {seconds:.1f} s", flush=True)


if __name__ == "__main__":
    sys.exit(main())

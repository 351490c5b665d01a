"""Compile (or load) the numba kernels of a whole run once, in one process, into numba's cache.

`python -m experiments.bench.warm` runs every extractor on a small scan (`local.warm_kernels`),
then a short simulated drive through the loop once per association method, with the single-scan
and the window associator, loop closure on, the smoother's input and the GPS scoring: the kernels
and signatures a run and the test suite use. `make test`, `make check` and CI run it before
the test workers start (tests/conftest.py), into a cache folder that each worker then copies
as its own: a fresh clone compiles each kernel once instead of once per worker.

It prints one line when it starts and one with its time, so a cold first run is not a silence.
"""

from __future__ import annotations

import sys
import time

__all__ = ["warm_every_kernel"]

WARM_SCANS = 30  # enough for landmarks to join the map, be re-observed and the window to fill


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
    return time.perf_counter() - t0


def _warm_unicycle() -> None:
    """The unicycle model's kernel, which no Cycab drive uses (its tests compiled it in each
    test worker, about 3 s of CPU every run)."""
    import numpy as np

    from slam.motion import UnicycleMotion

    t = np.linspace(0.0, 1.0, 5)
    UnicycleMotion(t, np.ones(5), np.zeros(5)).integrate(np.zeros(3), 0.0, 1.0)


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


def main() -> None:
    print("numba kernels: compiling or loading (a fresh clone: about a minute)", flush=True)
    seconds = warm_every_kernel()
    print(f"numba kernels: ready in {seconds:.1f} s", flush=True)


if __name__ == "__main__":
    sys.exit(main())

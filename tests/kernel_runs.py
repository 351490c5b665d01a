"""Kernels under a wall-clock bound (tests/ is on pytest's pythonpath): `Bounded` runs a call in
a worker process and fails the test when it does not return in time (a compiled loop without an
end cannot be stopped inside the process that runs it: it holds the main thread and ignores
SIGALRM); `extract_summary` and `slam_summary` are the calls, a configuration's settings driven
through the extractor's and the filter's kernels on a short simulated drive.
"""

from __future__ import annotations

import math
import multiprocessing as mp
from functools import lru_cache

import numpy as np
import pytest

# the extremes every setting is tried with: zero, subnormals, tiny and huge numbers, negative
# ones, non-finite ones, and integers far beyond 64 bits
EXTREMES = (0, 0.0, -0.0, 5e-324, -5e-324, 1e-310, 1e-300, 1e-150, 1e300, -1e300, -1, -1.0,
            1e8, 1e9, math.inf, -math.inf, math.nan, 2**63, 10**30, -(10**30))  # fmt: skip


class Bounded:
    """One worker process (spawned: no lock or thread state copied from this one) that runs
    `fn(*args)` and returns its value or raises its exception; a call that takes more than
    `timeout` seconds kills the worker and fails the test."""

    def __init__(self) -> None:
        self._pool = None

    def __call__(self, fn, *args, timeout: float):
        if self._pool is None:
            self._pool = mp.get_context("spawn").Pool(1)
        pending = self._pool.apply_async(fn, args)
        try:
            return pending.get(timeout)
        except mp.TimeoutError:
            self.close()
            pytest.fail(f"{fn.__name__}{args!r} did not return in {timeout} s")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None


@lru_cache(maxsize=1)
def _drive():
    """A 6-scan simulated Cycab drive through the tree park (the worker's own, made once)."""
    from experiments.sim import CycabParams, simulate_cycab_run

    return simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=6))


def extract_summary(settings: dict) -> dict:
    """The configuration `settings` ({section: {setting: value}}) loaded, then its extractor run
    on every scan of the drive: (circles found, whether every number in them is finite) by
    method. Raises what loading or extracting raises."""
    from features import extract_features
    from slam import SlamConfig

    cfg = SlamConfig.from_dict(settings)
    seq = _drive()
    methods = ["bailey"] if cfg.features.method == "bailey" else ["paper", "geometric", "kasa"]
    out = {}
    for method in methods:
        params, options = cfg.features.extractor_args()
        n, finite = 0, True
        for k in range(seq.n_scans):
            feats = extract_features(seq.scan(k), method, params, **options)
            n += feats.circle_params.shape[0]
            finite &= bool(np.isfinite(feats.circle_params).all())
            finite &= bool(np.isfinite(feats.circle_cov).all())
        out[method] = (n, finite)
    return out


def slam_summary(settings: dict) -> dict:
    """The configuration `settings` loaded, then the filter run on the drive with it: the
    landmarks mapped and whether the last pose and its covariance are finite."""
    from slam import SlamConfig, run_slam

    cfg = SlamConfig.from_dict(settings)
    log = run_slam(_drive(), cfg)
    pose, cov = log.pose[-1], log.pose_cov[-1]
    return {
        "landmarks": int(log.landmark_id.size),
        "finite": bool(np.isfinite(pose).all() and np.isfinite(cov).all()),
    }


def paper_fit(lambda0: float, max_iter: int, tol: float) -> tuple:
    """`features.fitting.fit_circle_paper` called directly on a noisy 60 deg arc of the circle
    centred (3, 1) of radius 0.4 m: (x0, y0, r, ok, n_iter)."""
    from features.fitting import fit_circle_paper

    rng = np.random.default_rng(0)
    t = np.linspace(math.pi - 0.5, math.pi + 0.5, 12)
    x = 3.0 + 0.4 * np.cos(t) + 0.002 * rng.standard_normal(t.size)
    y = 1.0 + 0.4 * np.sin(t) + 0.002 * rng.standard_normal(t.size)
    x0, y0, r, ok, n_iter = fit_circle_paper(x, y, lambda0, max_iter, tol)
    return float(x0), float(y0), float(r), bool(ok), int(n_iter)

"""`trunkslam bench association`: time per scan of each association method at Victoria Park scale.

The scene: 200 mapped trunks and 20 trunks not yet in the map (min. 1.5 m apart) over a
160 m x 160 m park, so that about 10 are within the 20 m detection range; a 403-dimensional
EKF-SLAM state [pose, 200 landmarks] with a dense covariance (landmark errors correlated with
the pose, as after SLAM); all 200 features are passed to the association each scan (gating does
the culling); 2 clutter returns per scan; P_D 0.9. The vehicle drives 1 m between scans.
Each method sees the same scans, taken in turn scan by scan (so that background load hits
every method alike); the time is the wall time of one call (input checks, gating and the
method), after 5 untimed warm-up scans.
"""

from __future__ import annotations

import math
import time

import numpy as np

from experiments.bench import machine
from experiments.exp_association import _hard_core_points, predict_map
from experiments.export import markdown_table

__all__ = ["bench", "format_table", "vp_scale_scans"]

N_LANDMARKS = 200
N_UNMAPPED = 20
HALF_M = 80.0
MAX_RANGE_M = 20.0
WARMUP = 5


def vp_scale_scans(n_scans: int, seed: int = 0) -> list[dict]:
    """Scans of the benchmark scene: dicts with z, R, z_hat, H, P, pose (sensor, estimated)."""
    rng = np.random.default_rng(seed)
    lm_all = _hard_core_points(rng, (N_LANDMARKS + N_UNMAPPED) * 3, HALF_M, 1.5)
    lm_all = lm_all[: N_LANDMARKS + N_UNMAPPED]
    lm = lm_all[:N_LANDMARKS]  # the mapped ones
    n = lm.shape[0]
    d = 3 + 2 * n
    R = np.diag([0.1**2, math.radians(0.5) ** 2])
    sig_pose = np.array([0.3, 0.3, math.radians(1.0)])
    out = []
    pose = np.array([-60.0, -60.0, math.pi / 4])
    for _ in range(n_scans):
        pose = pose + np.array([math.cos(pose[2]), math.sin(pose[2]), rng.normal(0, 0.03)])
        if np.abs(pose[:2]).max() > HALF_M - 20:  # stay inside the park: turn around
            pose[2] += math.pi
        # dense P: independent landmark errors + a common part correlated with the pose error
        U = np.zeros((d, 3))
        U[:3] = np.diag(sig_pose)
        U[3:] = np.tile(np.diag(sig_pose[:2] * 0.8), (n, 1)) @ np.eye(2, 3)
        D = np.full(d, 0.1**2)
        D[:3] = 1e-6
        P = U @ U.T + np.diag(D)
        err = U @ rng.normal(size=3) + np.sqrt(D) * rng.normal(size=d)
        est = pose + err[:3]
        z_hat, H, _ = predict_map(est, np.zeros((3, 3)), lm + err[3:].reshape(n, 2), 0.0)
        dx, dy = lm_all[:, 0] - pose[0], lm_all[:, 1] - pose[1]
        r = np.hypot(dx, dy)
        seen = np.flatnonzero((r <= MAX_RANGE_M) & (rng.random(r.size) < 0.9))
        z = np.column_stack([r[seen], np.arctan2(dy[seen], dx[seen]) - pose[2]])
        z = z + rng.multivariate_normal(np.zeros(2), R, seen.size).reshape(-1, 2)
        zc = np.column_stack([rng.uniform(1, MAX_RANGE_M, 2), rng.uniform(-np.pi, np.pi, 2)])
        z = np.vstack([z, zc])
        z[:, 1] = np.pi - np.mod(np.pi - z[:, 1], 2 * np.pi)
        out.append({"z": z, "R": R, "z_hat": z_hat, "H": H, "P": P, "pose": est})
    return out


def _stats(times_s: list[float]) -> tuple[float, float]:
    t = np.asarray(times_s) * 1e3
    return float(np.median(t)), float(np.percentile(t, 90))


def bench(repeats: int = 200, seed: int = 0) -> list[dict]:
    """Rows (method, median_ms, p90_ms, notes): wall time per scan over `repeats` scans."""
    from association import SlidingWindowAssociator, associate_detailed
    from association._inputs import prepare

    if repeats < 1:
        raise ValueError(f"repeats: must be >= 1, got {repeats}")
    scans = vp_scale_scans(repeats + WARMUP, seed)
    m_mean = np.mean([s["z"].shape[0] for s in scans])
    args = ("z", "R", "z_hat", "H", "P")
    win = SlidingWindowAssociator(K=3)
    Q_rel = np.diag([0.02**2, 0.02**2, math.radians(0.2) ** 2])

    def window(s):
        win.step(*(s[a] for a in args), sensor_pose=s["pose"], sensor_pose_cov=Q_rel)
        return win.last

    methods = {
        "checks": lambda s: prepare(*(s[a] for a in args), 0.99),
        "ihgr": lambda s: associate_detailed(*(s[a] for a in args), "ihgr"),
        "ihgr_nopre": lambda s: associate_detailed(*(s[a] for a in args), "ihgr", presolve=False),
        "window": window,
        "jcbb": lambda s: associate_detailed(*(s[a] for a in args), "jcbb"),
        "nn": lambda s: associate_detailed(*(s[a] for a in args), "nn"),
    }
    times: dict[str, list[float]] = {k: [] for k in methods}
    infos: dict[str, list] = {k: [] for k in methods}
    for k, s in enumerate(scans):  # round robin: every method on this scan, then the next scan
        for name, fn in methods.items():
            t0 = time.perf_counter()
            info = fn(s)
            dt = time.perf_counter() - t0
            if k >= WARMUP:
                times[name].append(dt)
                infos[name].append(info)

    rows = [("input checks + gating only", *_stats(times["checks"]), "common to every method")]
    lp = np.array([i.lp_solves for i in infos["ihgr"]])
    rows.append(
        (
            "IHGR single scan",
            *_stats(times["ihgr"]),
            f"{(lp > 0).mean():.1%} of scans needed an LP (max {lp.max()} solves); "
            "the rest were settled by presolve",
        )
    )
    lp = np.array([i.lp_solves for i in infos["ihgr_nopre"]])
    rows.append(
        (
            "IHGR single scan, presolve off",
            *_stats(times["ihgr_nopre"]),
            f"every scan through linprog (HiGHS), mean {lp.mean():.2f} solves",
        )
    )
    info = infos["window"]
    rows.append(
        (
            "IHGR K = 3 window",
            *_stats(times["window"]),
            f"mean {np.mean([i.n_tracks for i in info]):.1f} track hypotheses, "
            f"{np.mean([i.rounding.lp_solves > 0 for i in info]):.1%} of scans needed an LP "
            f"(max {max(i.rounding.lp_solves for i in info)} solves)",
        )
    )
    nodes = np.array([i.nodes for i in infos["jcbb"]])
    hits = sum(i.budget_exhausted for i in infos["jcbb"])
    rows.append(
        (
            "JCBB (node budget 20000)",
            *_stats(times["jcbb"]),
            f"nodes: median {np.median(nodes):.0f}, max {nodes.max()}; budget exhausted "
            f"in {hits} scans",
        )
    )
    rows.append(("NN (gated, greedy)", *_stats(times["nn"]), ""))
    return [
        {
            "method": r[0],
            "median_ms": round(r[1], 3),
            "p90_ms": round(r[2], 3),
            "notes": r[3]
            + (
                f" [{m_mean:.1f} measurements, {N_LANDMARKS} features, state {3 + 2 * N_LANDMARKS}]"
                if r[0].startswith("input")
                else ""
            ),
        }
        for r in rows
    ]


def format_table(rows: list[dict]) -> str:
    """Markdown table of `bench` rows, with the machine."""
    body = markdown_table(
        ["method", "median ms/scan", "p90 ms/scan", "notes"],
        [[r["method"], r["median_ms"], r["p90_ms"], r["notes"]] for r in rows],
    )
    return f"Association time per scan at Victoria Park scale ({machine()})\n\n{body}"

"""`trunkslam bench association`: time per scan of each association method at Victoria Park scale.

The scene is `experiments.sim.landmarks.vp_scale_scans`: 200 mapped trunks and 20 not yet in the
map over a 160 m x 160 m park, about 10 within the 20 m range, a 403-dimensional state with a
dense covariance, 2 clutter returns per scan, P_D 0.9. Each method sees the same scans, taken in
turn scan by scan (so that background load hits every method alike); the time is the wall time
of one call (input checks, gating and the method), after 5 untimed warm-up scans.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from experiments.errors import ConfigError
from experiments.io.provenance import machine
from experiments.io.writers import markdown_table
from experiments.sim.landmarks import N_LANDMARKS, vp_scale_scans

__all__ = ["bench", "format_table"]

WARMUP = 5


def _stats(times_s: list[float]) -> tuple[float, float]:
    t = np.asarray(times_s) * 1e3
    return float(np.median(t)), float(np.percentile(t, 90))


def _timed_calls() -> dict[str, Callable[[dict], object]]:
    """The calls timed, by name: the input checks and gating alone, each method on one scan
    (IHGR with and without presolve; the K = 3 window, fed every scan in turn)."""
    from association import SlidingWindowAssociator, associate_detailed
    from association.inputs import prepare
    from experiments.paper.association import STUDY_GATE_PROB

    args = ("z", "R", "z_hat", "H", "P")
    win = SlidingWindowAssociator(K=3, gate_prob=STUDY_GATE_PROB)
    Q_rel = np.diag([0.02**2, 0.02**2, math.radians(0.2) ** 2])

    def window(s):
        win.step(*(s[a] for a in args), sensor_pose=s["pose"], sensor_pose_cov=Q_rel)
        return win.last

    return {
        "checks": lambda s: prepare(*(s[a] for a in args), STUDY_GATE_PROB),
        "ihgr": lambda s: associate_detailed(
            *(s[a] for a in args), "ihgr", gate_prob=STUDY_GATE_PROB
        ),
        "ihgr_nopre": lambda s: associate_detailed(
            *(s[a] for a in args), "ihgr", presolve=False, gate_prob=STUDY_GATE_PROB
        ),
        "window": window,
        "jcbb": lambda s: associate_detailed(
            *(s[a] for a in args), "jcbb", gate_prob=STUDY_GATE_PROB
        ),
        "nn": lambda s: associate_detailed(*(s[a] for a in args), "nn", gate_prob=STUDY_GATE_PROB),
    }


def _round_robin(scans: list[dict], calls: dict, progress) -> tuple[dict, dict]:
    """(seconds, results) per call over the scans after the warm-up: every call on a scan,
    then the next scan, so that background load hits every method alike."""
    times: dict[str, list[float]] = {k: [] for k in calls}
    infos: dict[str, list] = {k: [] for k in calls}
    for k, s in enumerate(scans):
        if progress is not None and k % 10 == 0:
            progress("association scans", k, len(scans))
        for name, fn in calls.items():
            t0 = time.perf_counter()
            info = fn(s)
            dt = time.perf_counter() - t0
            if k >= WARMUP:
                times[name].append(dt)
                infos[name].append(info)
    if progress is not None:
        progress("association scans", len(scans), len(scans))
    return times, infos


def _notes(infos: dict) -> dict[str, str]:
    """What each method's results say beside its time (LP solves, tracks, JCBB's nodes)."""
    lp = np.array([i.lp_solves for i in infos["ihgr"]])
    lp_off = np.array([i.lp_solves for i in infos["ihgr_nopre"]])
    win = infos["window"]
    nodes = np.array([i.nodes for i in infos["jcbb"]])
    hits = sum(i.budget_exhausted for i in infos["jcbb"])
    return {
        "checks": "common to every method",
        "ihgr": f"{(lp > 0).mean():.1%} of scans needed an LP (max {lp.max()} solves); "
        "the rest were settled by presolve",
        "ihgr_nopre": f"every scan through linprog (HiGHS), mean {lp_off.mean():.2f} solves",
        "window": f"mean {np.mean([i.n_tracks for i in win]):.1f} track hypotheses, "
        f"{np.mean([i.rounding.lp_solves > 0 for i in win]):.1%} of scans needed an LP "
        f"(max {max(i.rounding.lp_solves for i in win)} solves)",
        "jcbb": f"nodes: median {np.median(nodes):.0f}, max {nodes.max()}; budget exhausted "
        f"in {hits} scans",
        "nn": "",
    }


# the rows of the table: (call, method as the table names it)
METHOD_NAMES = (
    ("checks", "input checks + gating only"),
    ("ihgr", "IHGR single scan"),
    ("ihgr_nopre", "IHGR single scan, presolve off"),
    ("window", "IHGR K = 3 window"),
    ("jcbb", "JCBB (node budget 20000)"),
    ("nn", "NN (gated, greedy)"),
)


def bench(
    repeats: int = 200, seed: int = 0, progress: Callable[[str, int, int], None] | None = None
) -> list[dict]:
    """Rows (method, median_ms, p90_ms, notes): wall time per scan over `repeats` scans.
    progress(description, done, total) is called between scans, never inside a timed call."""
    if repeats < 1:
        raise ConfigError(f"repeats: must be >= 1, got {repeats}")
    scans = vp_scale_scans(repeats + WARMUP, seed)
    m_mean = np.mean([s["z"].shape[0] for s in scans])
    times, infos = _round_robin(scans, _timed_calls(), progress)
    notes = _notes(infos)
    scale = f" [{m_mean:.1f} measurements, {N_LANDMARKS} features, state {3 + 2 * N_LANDMARKS}]"
    rows = []
    for call, method in METHOD_NAMES:
        median, p90 = _stats(times[call])
        rows.append(
            {
                "method": method,
                "median_ms": round(median, 3),
                "p90_ms": round(p90, 3),
                "notes": notes[call] + (scale if method.startswith("input") else ""),
            }
        )
    return rows


def format_table(rows: list[dict]) -> str:
    """Markdown table of `bench` rows, with the machine."""
    body = markdown_table(
        ["method", "median ms/scan", "p90 ms/scan", "notes"],
        [[r["method"], r["median_ms"], r["p90_ms"], r["notes"]] for r in rows],
    )
    return f"Association time per scan at Victoria Park scale ({machine()})\n\n{body}"

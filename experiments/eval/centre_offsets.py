"""Where a circle fit puts a simulated trunk's centre, against the truth, pass by pass.

With the truth known, each circle on a trunk's beams gives an offset: its centre, placed in the
world with the laser's true pose, minus the trunk's true centre, split along the line of sight
from the laser to the true centre ("range") and across it ("across", positive to the left).
A trunk's sightings form passes: runs with no gap longer than `gap_s` (2 s, the pass of
`experiments.eval.trunk_offsets.view_offset`). Per axis, over the passes with at least
`min_sightings` sightings (`pass_statistics`):

  mean_m         the mean offset over all sightings (a bias the filter may correct)
  pass_sd_m      the spread of the passes' mean offsets about `mean_m` that white noise does not
                 explain: sqrt(max(var(pass means) - mean(within-pass var / n), 0)). A circular
                 trunk gives about 0; a trunk whose fitted centre depends on the view gives the
                 offset a pass shares.
  white_sd_m     the sd of the offsets about their own pass's mean (what changes scan to scan)
  lag1           the correlation of consecutive sightings' offsets within a pass, both taken
                 about `mean_m`: about 0 for white errors, near 1 for an offset that persists
  share          the passes' share of the offsets' variance, pass_sd^2 / (pass_sd^2 + white_sd^2)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from experiments.eval.detections import dominant_label, run_labels
from slam import se2

__all__ = ["AXES", "PassStatistics", "pass_statistics", "sighting_offsets"]

AXES = ("range", "across")


@dataclass(frozen=True)
class PassStatistics:
    """One axis's figures (module doc); passes: how many passes counted, sightings: in them."""

    passes: int
    sightings: int
    mean_m: float
    pass_sd_m: float
    white_sd_m: float
    lag1: float
    share: float


def sighting_offsets(
    seq, feats: list, laser_world: np.ndarray, match_m: float = 0.5
) -> dict[str, np.ndarray]:
    """Every circle of `feats` (one `Features` per scan of `seq`) whose beams with a return mostly
    hit one of the scene's landmarks and whose centre lies within `match_m` of it.

    laser_world (N, 3): the laser's true world pose at each scan.
    Returns t (M,) the scan time, s; landmark (M,) its label; offset (M, 2) [range, across], m
    (module doc); bearing (M,) the world direction from the laser to the true centre, rad.
    """
    lm = seq.truth_landmarks
    t, lab, off, bearing = [], [], [], []
    for k, f in enumerate(feats):
        labels = seq.scan_labels[k]
        for (a, b), p in zip(f.circle_beams, f.circle_params):
            j, count, n_ret = dominant_label(run_labels(labels, a, b), returns_only=True)
            if n_ret == 0 or j >= lm.shape[0] or 2 * count <= n_ret:
                continue
            d = se2.transform_points(laser_world[k], p[:2]) - lm[j, :2]
            los = lm[j, :2] - laser_world[k, :2]
            u = los / np.hypot(*los)
            if np.hypot(*d) > match_m:
                continue
            t.append(seq.scan_t[k])
            lab.append(j)
            off.append([d @ u, u[0] * d[1] - u[1] * d[0]])
            bearing.append(math.atan2(u[1], u[0]))
    return {
        "t": np.array(t, dtype=np.float64),
        "landmark": np.array(lab, dtype=np.int64),
        "offset": np.array(off, dtype=np.float64).reshape(-1, 2),
        "bearing": np.array(bearing, dtype=np.float64),
    }


def passes(t: np.ndarray, landmark: np.ndarray, gap_s: float = 2.0) -> list[np.ndarray]:
    """Indices of each pass (module doc), in time order within each pass."""
    out = []
    for j in np.unique(landmark):
        seen = np.flatnonzero(landmark == j)
        seen = seen[np.argsort(t[seen], kind="stable")]
        out += np.split(seen, np.flatnonzero(np.diff(t[seen]) > gap_s) + 1)
    return out


def pass_statistics(
    sightings: dict[str, np.ndarray], gap_s: float = 2.0, min_sightings: int = 5
) -> dict[str, PassStatistics]:
    """Per axis ("range", "across"), the figures of the module doc over the passes of at least
    `min_sightings` sightings. Raises ValueError when no pass qualifies."""
    groups = [
        p for p in passes(sightings["t"], sightings["landmark"], gap_s) if p.size >= min_sightings
    ]
    if not groups:
        raise ValueError("pass_statistics: no pass has enough sightings")
    out = {}
    for axis, name in enumerate(AXES):
        x = [sightings["offset"][p, axis] for p in groups]
        allx = np.concatenate(x)
        mean = float(allx.mean())
        means = np.array([v.mean() for v in x])
        within = np.array([v.var(ddof=1) / v.size for v in x])
        between = max(float(means.var(ddof=1)) - float(within.mean()), 0.0) if len(x) > 1 else 0.0
        resid = np.concatenate([v - v.mean() for v in x])
        white = float(np.sqrt(np.sum(resid**2) / (resid.size - len(x))))
        num = sum(float(np.sum((v[1:] - mean) * (v[:-1] - mean))) for v in x)
        den = sum(float(np.sum((v - mean) ** 2)) for v in x)
        out[name] = PassStatistics(
            passes=len(x),
            sightings=int(allx.size),
            mean_m=mean,
            pass_sd_m=math.sqrt(between),
            white_sd_m=white,
            lag1=num / den if den > 0 else math.nan,
            share=between / (between + white**2) if between + white**2 > 0 else math.nan,
        )
    return out

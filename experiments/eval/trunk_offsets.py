"""How far a trunk's measured centre moves with the side it is seen from (`view_offset`).

The filter takes each circle's centre as a measurement with white noise, so a landmark seen
hundreds of times is placed to a few millimetres relative to its neighbours. A real trunk is
not a circle: its measured centre is pulled along the line of sight by a bias that depends on
the tree (bark, ovality, a fit's radius error), and that bias does not average away over the
scans of one pass. Loop closure's rigid-fit test (`slam.closure`, `closure.tree_sd_m`) adds
it back as an independent error of each landmark.

The procedure, on a run's log: every pass of a landmark (its sightings with no gap longer than
`gap_s`, at least `min_sightings` of them, over which the line of sight turns by at least
`min_turn_deg`) gives the world position of each measurement (the logged pose, the laser's
mounting, the measured range and bearing) and the unit line of sight u_i. Least squares fits
p_i = c + b u_i: the pass's centre c and its radial bias b. Over the passes, the mean of b^2
less the mean of its least-squares variance (the white noise's share) is the bias's variance;
seen from a direction spread evenly around the tree, that is b^2 / 2 per axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slam import se2

__all__ = ["ViewOffset", "view_offset"]


@dataclass(frozen=True)
class ViewOffset:
    """passes: those fitted; bias_mean_m, bias_rms_m: of the fitted radial biases b;
    noise_var_m2: the mean variance of b from the residuals; sd_per_axis_m:
    sqrt(max(mean b^2 - noise_var_m2, 0) / 2), the centre's error per axis over all sides."""

    passes: int
    bias_mean_m: float
    bias_rms_m: float
    noise_var_m2: float
    sd_per_axis_m: float


def view_offset(
    log,
    n_scans: int | None = None,
    *,
    gap_s: float = 2.0,
    min_sightings: int = 10,
    min_turn_deg: float = 30.0,
) -> ViewOffset:
    """The trunks' view-dependent centre offset (module doc) over the log's first `n_scans`
    scans (all when None). Raises ValueError when no pass qualifies."""
    n = log.n_scans if n_scans is None else min(int(n_scans), log.n_scans)
    m = log.obs_scan < n
    scan, lid, z = log.obs_scan[m], log.obs_landmark[m], log.obs_z[m]
    pose = log.pose[scan]
    lp = np.asarray(log.laser_pose, dtype=np.float64)
    sight = pose[:, 2] + lp[2] + z[:, 1]  # world direction from the laser to the trunk
    u = np.stack([np.cos(sight), np.sin(sight)], axis=1)
    world = se2.observed_points(pose, z, lp)
    t = log.scan_t[scan]
    bias, var = [], []
    for landmark in np.unique(lid):
        seen = np.flatnonzero(lid == landmark)
        seen = seen[np.argsort(t[seen], kind="stable")]
        for p in np.split(seen, np.flatnonzero(np.diff(t[seen]) > gap_s) + 1):
            turn = np.ptp(np.unwrap(sight[p])) if p.size else 0.0
            if p.size < min_sightings or turn < math.radians(min_turn_deg):
                continue
            A = np.zeros((2 * p.size, 3))
            A[0::2, 0] = A[1::2, 1] = 1.0
            A[:, 2] = u[p].reshape(-1)
            y = world[p].reshape(-1)
            sol = np.linalg.lstsq(A, y, rcond=None)[0]
            r = y - A @ sol
            bias.append(sol[2])
            var.append((r @ r) / (y.size - 3) * np.linalg.inv(A.T @ A)[2, 2])
    if not bias:
        raise ValueError("view_offset: no pass of a landmark qualifies")
    b, v = np.array(bias), np.array(var)
    return ViewOffset(
        passes=int(b.size),
        bias_mean_m=float(b.mean()),
        bias_rms_m=float(np.sqrt(np.mean(b**2))),
        noise_var_m2=float(v.mean()),
        sd_per_axis_m=float(np.sqrt(max(np.mean(b**2) - v.mean(), 0.0) / 2.0)),
    )

"""The time series of one SLAM run that the recordings plot beside the map: pose error with its
3-sigma bounds (when the sequence has truth), NIS with its 95% bounds, the innovations with their
2-sigma bounds, map size and time per scan.

Each is a `Series`: values at scans (indices into the run's scans), one column per curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from experiments.eval.poses import pose_errors
from slam import SlamLog, interpolate_poses

__all__ = ["SLAM_PANELS", "Series", "slam_panels", "slam_series"]

# (name, title with unit) of every series a run can have, in display order
SLAM_PANELS = (
    ("pose_error/x", "x error (m), +-3 sigma"),
    ("pose_error/y", "y error (m), +-3 sigma"),
    ("pose_error/theta", "heading error (deg), +-3 sigma"),
    ("nis", "NIS per scan, 95% bounds"),
    ("innovation/range", "range innovation (m), +-2 sigma"),
    ("innovation/bearing", "bearing innovation (deg), +-2 sigma"),
    ("map_size", "map size (landmarks, tentatives)"),
    ("ms_per_scan", "time per scan (ms)"),
)
_TITLE = dict(SLAM_PANELS)


def slam_panels(has_truth: bool) -> list[tuple[str, str]]:
    """The (name, title) of the panels of a run, pose errors only with truth."""
    return [p for p in SLAM_PANELS if has_truth or not p[0].startswith("pose_error")]


@dataclass(frozen=True, eq=False)
class Series:
    """name: path-like name ("pose_error/x"); title: the panel's title with the unit;
    scan (n,) int: scan index of each row (repeated for several rows a scan); values (n, k):
    one column per curve, named by `curves` (k,); points: draw markers rather than lines (one
    row per observation)."""

    name: str
    title: str
    scan: np.ndarray
    values: np.ndarray
    curves: tuple[str, ...]
    points: bool = False

    def __post_init__(self) -> None:
        if self.values.ndim != 2 or self.values.shape != (self.scan.size, len(self.curves)):
            raise ValueError(
                f"Series.values: expected shape ({self.scan.size}, {len(self.curves)}), "
                f"got {self.values.shape}"
            )


def slam_series(lg: SlamLog, truth_t=None, truth_pose=None) -> list[Series]:
    """The series of one run (`slam.run_slam`'s log). With truth (times (T,), poses (T, 3) of the
    rear-axle centre), the pose error after each update against the truth at the scan times the
    truth covers, with +-3 sigma of the filter's covariance."""
    n = lg.n_scans
    scans = np.arange(n)
    out: list[Series] = []
    if truth_t is not None and truth_pose is not None:
        inside = (lg.scan_t >= truth_t[0]) & (lg.scan_t <= truth_t[-1])
        k = scans[inside]
        ref = interpolate_poses(lg.scan_t[inside], truth_t, truth_pose)
        e = pose_errors(lg.pose[inside], ref)
        sig = 3.0 * np.sqrt(np.maximum(np.diagonal(lg.pose_cov[inside], axis1=1, axis2=2), 0.0))
        for i, (name, scale) in enumerate((("x", 1.0), ("y", 1.0), ("theta", 180 / np.pi))):
            v = scale * np.column_stack([e[:, i], sig[:, i], -sig[:, i]])
            name = f"pose_error/{name}"
            out.append(Series(name, _TITLE[name], k, v, ("error", "+3 sigma", "-3 sigma")))
    ok = lg.scan_nis_dof > 0
    dof = lg.scan_nis_dof[ok]
    lo, hi = chi2.ppf(0.025, dof), chi2.ppf(0.975, dof)
    out.append(
        Series(
            "nis",
            _TITLE["nis"],
            scans[ok],
            np.column_stack([lg.scan_nis[ok], hi, lo]),
            ("NIS", "97.5%", "2.5%"),
        )
    )
    if lg.obs_scan.size:
        s2 = 2.0 * np.sqrt(np.maximum(np.diagonal(lg.obs_innov_cov, axis1=1, axis2=2), 0.0))
        for i, (name, scale) in enumerate((("range", 1.0), ("bearing", 180 / np.pi))):
            v = scale * np.column_stack([lg.obs_innov[:, i], s2[:, i], -s2[:, i]])
            name = f"innovation/{name}"
            out.append(
                Series(
                    name,
                    _TITLE[name],
                    np.asarray(lg.obs_scan, int),
                    v,
                    ("innovation", "+2 sigma", "-2 sigma"),
                    points=True,
                )
            )
    out.append(
        Series(
            "map_size",
            _TITLE["map_size"],
            scans,
            np.column_stack([lg.n_map, lg.n_tentative]).astype(float),
            ("landmarks", "tentatives"),
        )
    )
    out.append(
        Series(
            "ms_per_scan",
            _TITLE["ms_per_scan"],
            scans,
            1e3 * np.asarray(lg.timing_s["total"], float)[:, None],
            ("total",),
        )
    )
    return out

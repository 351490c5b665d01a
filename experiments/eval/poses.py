"""Pose errors against a reference, and filter consistency (NEES, NIS) with chi-square bounds.

Definitions (docs/method.md section 5):
  pose error   estimate minus reference, [dx_m, dy_m, dtheta_rad] with the heading wrapped.
  NEES         e^T P^-1 e of each pose (3 dof); averaged over R Monte Carlo runs, its 95% bounds
               are chi2_(3R)(0.025, 0.975) / R.
  NIS          per scan, the batch NIS summed over the runs against the chi-square bounds of the
               summed degrees of freedom; NIS per dof is the overall ratio (1 when consistent).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from slam import wrap_angle

__all__ = ["consistency", "nees", "nees_bounds", "pose_errors"]


def pose_errors(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(N, 3) est - ref for poses (N, 3) [x, y, theta]; the heading difference wrapped."""
    e = np.asarray(est, dtype=np.float64) - np.asarray(ref, dtype=np.float64)
    e[:, 2] = wrap_angle(e[:, 2])
    return e


def nees(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(N,) e_k^T P_k^-1 e_k for errors (N, d) and covariances (N, d, d)."""
    return np.array([float(e @ np.linalg.solve(C, e)) for e, C in zip(err, cov)])


def nees_bounds(n_runs: int, dof: int = 3) -> tuple[float, float]:
    """95% bounds of the average NEES over n_runs runs (chi2_(n d) / n)."""
    lo, hi = chi2.ppf([0.025, 0.975], dof * n_runs) / n_runs
    return float(lo), float(hi)


def consistency(nees_runs: np.ndarray, nis_runs: np.ndarray, nis_dof_runs: np.ndarray) -> dict:
    """NEES and NIS figures of a Monte Carlo study of R runs and N scans.

    nees_runs (R, N): pose NEES per run and scan; column 0 is left out (a run that starts at the
    truth has zero covariance there). nis_runs, nis_dof_runs (R, N): each scan's batch NIS and
    its degrees of freedom (0: no update). Returns the mean NEES, the fraction of scans whose
    run-averaged NEES is inside, below and above its 95% bounds (and the bounds and the average
    itself), the NIS per dof and the fraction of scans whose summed NIS is inside its bounds.
    """
    R = nees_runs.shape[0]
    avg = np.nanmean(nees_runs[:, 1:], axis=0)
    lo, hi = nees_bounds(R)
    nis_sum = np.nansum(np.where(nis_dof_runs > 0, nis_runs, 0.0), axis=0)
    dof_sum = nis_dof_runs.sum(axis=0)
    ok = dof_sum > 0
    nlo = chi2.ppf(0.025, dof_sum[ok])
    nhi = chi2.ppf(0.975, dof_sum[ok])
    inside_nis = (nis_sum[ok] >= nlo) & (nis_sum[ok] <= nhi)
    return {
        "nees_mean": float(np.mean(avg)),
        "nees_in": float(np.mean((avg >= lo) & (avg <= hi))),
        "nees_below": float(np.mean(avg < lo)),
        "nees_above": float(np.mean(avg > hi)),
        "nees_lo": lo,
        "nees_hi": hi,
        "nees_avg": avg,
        "nis_per_dof": float(nis_sum.sum() / dof_sum.sum()) if dof_sum.sum() else math.nan,
        "nis_in": float(np.mean(inside_nis)) if inside_nis.size else math.nan,
    }

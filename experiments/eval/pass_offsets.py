"""The trunk's centre offset shared by the sightings of one pass (`measurement.pass_offset_sd_m`),
derived by leave-one-pass-out prediction (`pass_offset`): a criterion that can see correlated
error, which the filter's own innovation likelihood (the calibration's J) cannot (it assumes
white errors and always prefers NIS 1).

A pass of a landmark is its run of sightings with no gap longer than `gap_s` (the filter's
rule, `slam.measurement.pass_sizes`). Each pass p of a landmark seen in at least two passes
gives (`passes_of`) the mean m_p of its sightings' world points (the filter's pose at the
scan, the laser's mounting, the measured range and bearing), the mean line of sight u_p, the
number of sightings n_p and the mean white variances per axis: r_range (R_rr) and r_across
(range^2 R_bb). Under the model, m_p = c + b_p + white, with b_p ~ N(0, U_p diag(s_r^2, s_a^2)
U_p^T) the pass's shared offset (U_p = [u_p, u_p rotated by 90 deg]), so its covariance is

    C_p = U_p diag(s_r^2 + r_range/n_p, s_a^2 + r_across/n_p) U_p^T.

Held out, pass p is predicted by the information-weighted mean of the landmark's other passes
(covariance C_pred, the inverse of their summed information); the residual e = m_p - prediction
has covariance C_p + C_pred, and its normalised square on each axis of p (e along u_p, and
across it, each over its variance) is chi-square with one degree of freedom when the model
holds. (s_r, s_a) are chosen so that the MEDIAN of each axis's normalised squares over all
held-out passes is the chi-square(1) median 0.4549: the median, not the mean, so that wrong
associations and a heavy tail (a pass of another tree, a merged pair) move it little (in
synthetic passes, 5% of them 1-3 m off raise s by about 20%, where the mean is theirs). Each
axis is a root found by bisection on ln s, alternating between the axes until neither moves;
an axis whose white model already has a median at or below 0.4549 gets s = 0.

What it absorbs: everything that moves a pass's mean as a whole and differs between passes,
the trunk's view-dependent centre offset and equally a pose error shared by the scans of a pass
(the filter's drift between passes), as the filter's inflation does. What it cannot see: the
poses are the filter's own, already corrected by the pass's earlier sightings and the map of
the other passes, which pulls m_p towards the prediction (s is then, if anything, too small).
No GPS enters it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from experiments.errors import DataError
from slam import se2
from slam.measurement import pass_sizes

__all__ = ["CHI2_1_MEDIAN", "PassOffset", "Passes", "pass_offset", "passes_of", "held_out"]

CHI2_1_MEDIAN = 0.454936423119572  # scipy.stats.chi2(1).median()
S_MAX_M = 5.0  # the search's upper end: a trunk's centre offset is never metres
TOL_LN = 1e-4  # bisection on ln s to this width
MAX_ROUNDS = 50  # of the alternation between the axes (Victoria Park: 14)


@dataclass(frozen=True)
class Passes:
    """P passes of landmarks seen in at least two passes; world frame, m.

    landmark (P,) int: the landmark of each pass; n (P,) int: its sightings; mean_xy (P, 2):
    the mean of their world points; u (P, 2): the unit mean line of sight (laser to trunk);
    r_range, r_across (P,): the mean white variances (m^2) along and across it."""

    landmark: np.ndarray
    n: np.ndarray
    mean_xy: np.ndarray
    u: np.ndarray
    r_range: np.ndarray
    r_across: np.ndarray

    def __post_init__(self) -> None:
        P = self.landmark.shape[0]
        for name, shape in (
            ("n", (P,)),
            ("mean_xy", (P, 2)),
            ("u", (P, 2)),
            ("r_range", (P,)),
            ("r_across", (P,)),
        ):
            v = getattr(self, name)
            if v.shape != shape:
                raise DataError(f"Passes.{name}: expected shape {shape}, got {v.shape}")
            if not np.all(np.isfinite(v)):
                raise DataError(f"Passes.{name}: values must be finite (NaN or inf found)")
        if P and (self.n.min() < 1 or self.r_range.min() <= 0 or self.r_across.min() <= 0):
            raise DataError("Passes: n must be >= 1 and the white variances > 0")
        _, count = np.unique(self.landmark, return_counts=True)
        if P == 0 or count.min() < 2:
            raise DataError(
                "Passes: the criterion needs landmarks seen in at least two passes "
                f"({P} passes given, each landmark's passes must be >= 2)"
            )


@dataclass(frozen=True)
class PassOffset:
    """The derived offset: sd_m (range, across) m; passes and landmarks used; median_white
    and median_derived (range, across): the median normalised squared residual of the
    held-out passes under the white model (s = 0) and at sd_m; rounds of the alternation.
    drift: the within-pass drift of the same run (`experiments.eval.pass_drift.DriftFit`),
    when it was fitted."""

    sd_m: tuple[float, float]
    passes: int
    landmarks: int
    median_white: tuple[float, float]
    median_derived: tuple[float, float]
    rounds: int
    drift: object = None


def passes_of(log, n_scans: int | None = None, gap_s: float = 2.0) -> Passes:
    """The passes (`Passes`) of a run's log (`slam.SlamLog`): its measurements used in an
    update (status >= 0, landmark as merged: meas_track) over the first `n_scans` scans, the
    filter's pose at each. Landmarks seen in one pass only are left out. A `DataError` when a
    value is not finite or no landmark has two passes."""
    n = log.scan_t.shape[0] if n_scans is None else min(int(n_scans), log.scan_t.shape[0])
    rows = np.flatnonzero((log.meas_status >= 0) & (log.meas_scan < n))
    scan, lid = log.meas_scan[rows], log.meas_track[rows]
    z, R = log.meas_z[rows], log.meas_R[rows]
    pose = log.pose[scan]
    for name, v in (("meas_z", z), ("meas_R", R), ("pose", pose)):
        if not np.all(np.isfinite(v)):
            raise DataError(f"pass offset: the log's {name} has NaN or inf values")
    lp = np.asarray(log.laser_pose, dtype=np.float64)
    world = se2.observed_points(pose, z, lp)
    sight = pose[:, 2] + lp[2] + z[:, 1]
    number, _ = pass_sizes(log.scan_t[scan], lid, gap_s)
    P = int(number.max()) + 1 if number.size else 0
    cnt = np.bincount(number, minlength=P).astype(np.float64)

    def mean(v):
        return np.bincount(number, weights=v, minlength=P) / np.maximum(cnt, 1)

    u = np.stack([mean(np.cos(sight)), mean(np.sin(sight))], axis=1)
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    landmark = np.zeros(P, np.int64)
    landmark[number] = lid
    keep = np.isin(landmark, np.unique(landmark)[np.unique(landmark, return_counts=True)[1] > 1])
    return Passes(
        landmark=landmark[keep],
        n=cnt[keep].astype(np.int64),
        mean_xy=np.stack([mean(world[:, 0]), mean(world[:, 1])], axis=1)[keep],
        u=u[keep],
        r_range=mean(R[:, 0, 0])[keep],
        r_across=mean(z[:, 0] ** 2 * R[:, 1, 1])[keep],
    )


def held_out(p: Passes, sd: tuple[float, float]) -> np.ndarray:
    """(P, 2) the normalised squared residual of each pass held out, along and across its
    line of sight, at offsets sd = (s_r, s_a) (module doc)."""
    U = np.stack([p.u, np.stack([-p.u[:, 1], p.u[:, 0]], axis=1)], axis=2)  # columns u, u_perp
    d = np.stack([sd[0] ** 2 + p.r_range / p.n, sd[1] ** 2 + p.r_across / p.n], axis=1)
    C = U @ (d[:, :, None] * np.swapaxes(U, 1, 2))  # U diag(d) U^T
    W = U @ ((1.0 / d)[:, :, None] * np.swapaxes(U, 1, 2))  # its inverse
    Wm = np.einsum("pij,pj->pi", W, p.mean_xy)
    _, group = np.unique(p.landmark, return_inverse=True)
    info = np.zeros((group.max() + 1, 2, 2))
    wsum = np.zeros((group.max() + 1, 2))
    np.add.at(info, group, W)
    np.add.at(wsum, group, Wm)
    others = info[group] - W
    others = 0.5 * (others + np.swapaxes(others, 1, 2))
    C_pred = np.linalg.inv(others)
    pred = np.einsum("pij,pj->pi", C_pred, wsum[group] - Wm)
    e = p.mean_xy - pred
    S = C + C_pred
    along = np.einsum("pi,pij->pj", e, U)  # e in the pass's axes
    var = np.einsum("pia,pij,pja->pa", U, S, U)
    return along**2 / var


def _median(p: Passes, sd, axis: int) -> float:
    return float(np.median(held_out(p, sd)[:, axis]))


def _solve_axis(p: Passes, sd: list, axis: int) -> float:
    """The s of `axis` (the other fixed) at which that axis's median is CHI2_1_MEDIAN; 0 when
    it is already at or below it with s = 0 (bisection on ln s)."""
    trial = list(sd)

    def f(s: float) -> float:
        trial[axis] = s
        return _median(p, trial, axis) - CHI2_1_MEDIAN

    if f(0.0) <= 0:
        return 0.0
    if f(S_MAX_M) > 0:
        raise DataError(
            f"pass offset: axis {('range', 'across')[axis]} needs more than {S_MAX_M} m; "
            "the passes do not describe one trunk each"
        )
    lo, hi = math.log(1e-6), math.log(S_MAX_M)
    if f(1e-6) <= 0:
        return 1e-6
    while hi - lo > TOL_LN:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(math.exp(mid)) > 0 else (lo, mid)
    return math.exp(0.5 * (lo + hi))


def pass_offset(p: Passes) -> PassOffset:
    """(s_r, s_a): each axis's median normalised squared residual of the held-out passes at the
    chi-square(1) median (module doc), alternating between the axes until neither moves by more
    than 0.1%."""
    sd = [0.0, 0.0]
    rounds, moved = 0, True
    while moved:
        if rounds == MAX_ROUNDS:
            raise DataError(
                f"pass offset: the axes' offsets still move after {MAX_ROUNDS} rounds ({sd})"
            )
        before = list(sd)
        for axis in (0, 1):
            sd[axis] = _solve_axis(p, sd, axis)
        rounds += 1
        moved = any(abs(a - b) > 1e-3 * max(a, b, 1e-9) for a, b in zip(sd, before))
    white = np.median(held_out(p, (0.0, 0.0)), axis=0)
    derived = np.median(held_out(p, tuple(sd)), axis=0)
    return PassOffset(
        sd_m=(float(sd[0]), float(sd[1])),
        passes=int(p.landmark.size),
        landmarks=int(np.unique(p.landmark).size),
        median_white=(float(white[0]), float(white[1])),
        median_derived=(float(derived[0]), float(derived[1])),
        rounds=rounds,
    )

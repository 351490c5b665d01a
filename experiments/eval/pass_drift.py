"""How a trunk's pass offset drifts as the view turns (`measurement.pass_offset_corr_rad`):
the within-pass semivariogram of the sightings' residuals against the view angle, fitted by a
first-order Gauss-Markov offset. A criterion that sees the correlation inside a pass, which the
leave-one-pass-out s (`experiments.eval.pass_offsets`, a constant offset per pass) cannot.

The model (the smoother's, `slam.smoother`): per landmark and pass, the sighting j's point is
the landmark c plus an offset b_j plus white noise w_j, with b stationary Gauss-Markov in the
view angle: Cov(b_j, b_k) = exp(-|tau_k - tau_j| / L) Sigma_b, where tau_j is the turn of the
line of sight accumulated from the pass's first sighting (the sum of |theta_{i+1} - theta_i|,
theta the world bearing of the line of sight; equal to |theta_k - theta_j| on a pass whose view
turns one way) and Sigma_b = U diag(s_r^2, s_a^2) U^T in the axes U of the pass's first line of
sight (range, across). Passes are independent.

The residual of a sighting (`sightings_of`) is its world point (the log's pose at its scan, the
laser's mounting, the measured range and bearing) minus its landmark's final estimate, in the
axes of its pass's first line of sight. For two sightings j, k of one pass the landmark's own
error cancels in e_j - e_k, and per axis a

    gamma(d) = 0.5 E[(e_j - e_k)^2 | |tau_k - tau_j| = d] = r + s^2 (1 - exp(-d / L))

(r: the white variance of one sighting on that axis, `r_eff`). `semivariogram` bins the pairs of
every pass by d; `fit_drift` fits (r_a, s_a^2) per axis and one L shared by the axes by weighted
least squares over the bins with at least `min_pairs` pairs (weights n_pairs / gamma_emp^2,
Cressie's approximation to the inverse variance of a bin's estimate), L by a search on a log
grid then golden section, (r, s^2) for a given L by non-negative least squares. Each axis's own
L is reported beside it. Pairs of sightings in two different passes of a landmark give the sill
r + s^2 of independent offsets (`Variogram.between`): s_between = sqrt(sill - r_eff) is the
cross-check of the fit's s (and of the leave-one-pass-out s, which sees only a pass's mean).

What it absorbs, as the leave-one-pass-out criterion does: whatever moves a pass's sightings
together, the trunk's view-dependent centre and equally the pose error the filter's poses share
over a few scans. No GPS enters it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from experiments.errors import DataError
from slam import se2
from slam.measurement import pass_sizes

__all__ = [
    "DriftFit",
    "Sightings",
    "Variogram",
    "fit_drift",
    "pass_drift",
    "semivariogram",
    "sightings_of",
]

DEFAULT_EDGES_RAD = np.linspace(0.0, math.pi / 2, 19)  # 5 deg bins up to 90 deg of turn
MIN_PAIRS = 30  # a bin with fewer pairs is not fitted
L_GRID = np.geomspace(1e-3, 1e3, 241)  # rad: the search's grid for the correlation length


@dataclass(frozen=True)
class Sightings:
    """m sightings; world frame, m, rad.

    pass_id (m,) int: the pass of each sighting (passes of different landmarks differ);
    landmark (m,) int; tau_rad (m,): the view's turn accumulated from its pass's first
    sighting; e (m, 2): the residual about the landmark's estimate along and across the pass's
    first line of sight; r (m, 2): the white variances of the sighting on those axes (m^2)."""

    pass_id: np.ndarray
    landmark: np.ndarray
    tau_rad: np.ndarray
    e: np.ndarray
    r: np.ndarray

    def __post_init__(self) -> None:
        m = self.pass_id.shape[0]
        for name, shape in (("landmark", (m,)), ("tau_rad", (m,)), ("e", (m, 2)), ("r", (m, 2))):
            v = getattr(self, name)
            if v.shape != shape:
                raise DataError(f"Sightings.{name}: expected shape {shape}, got {v.shape}")
            if not np.all(np.isfinite(v)):
                raise DataError(f"Sightings.{name}: values must be finite (NaN or inf found)")


@dataclass(frozen=True)
class Variogram:
    """The within-pass semivariogram: edges_rad (B + 1,) the bins of |tau_k - tau_j|;
    centre_rad (B,) the mean separation of each bin's pairs; pairs (B,); gamma (B, 2) m^2 along
    and across. between (2,) m^2 and between_pairs: the same over pairs of sightings of one
    landmark in two different passes (the sill r + s^2)."""

    edges_rad: np.ndarray
    centre_rad: np.ndarray
    pairs: np.ndarray
    gamma: np.ndarray
    between: np.ndarray
    between_pairs: int


@dataclass(frozen=True)
class DriftFit:
    """The fitted Gauss-Markov offset: corr_rad (L, shared by the axes), sd_m (s_r, s_a),
    r_eff_m2 (the white variance per axis), corr_axis_rad (each axis fitted alone; inf when
    that axis alone shows no drift within a pass, an end of `L_GRID` when its variogram rises
    without a sill (1000) or at once (0.001)), bins (the
    bins fitted), sd_between_m (sqrt(sill - r_eff) per axis, NaN when the sill is below
    r_eff), wsse (the fit's weighted squared error)."""

    corr_rad: float
    sd_m: tuple[float, float]
    r_eff_m2: tuple[float, float]
    corr_axis_rad: tuple[float, float]
    bins: int
    sd_between_m: tuple[float, float]
    wsse: float


def sightings_of(
    log, n_scans: int | None = None, gap_s: float = 2.0, pose=None, first_scan: int = 0
) -> Sightings:
    """The residuals (`Sightings`) of a run's log (`slam.SlamLog`): its measurements used in an
    update (status >= 0, landmark as merged) in scans [first_scan, n_scans), about the final
    map, at the log's poses (or `pose` (N, 3), e.g. a smoother's). Passes by the filter's gap
    rule."""
    n = log.scan_t.shape[0] if n_scans is None else min(int(n_scans), log.scan_t.shape[0])
    inside = (log.meas_scan < n) & (log.meas_scan >= first_scan)
    rows = np.flatnonzero((log.meas_status >= 0) & inside)
    rows = rows[np.isin(log.meas_track[rows], log.landmark_id)]
    rows = rows[np.lexsort((log.meas_scan[rows], log.meas_track[rows]))]
    scan, lid = log.meas_scan[rows], log.meas_track[rows]
    z, R = log.meas_z[rows], log.meas_R[rows]
    x = (log.pose if pose is None else np.asarray(pose, dtype=np.float64))[scan]
    for name, v in (("meas_z", z), ("meas_R", R), ("pose", x)):
        if not np.all(np.isfinite(v)):
            raise DataError(f"pass drift: the log's {name} has NaN or inf values")
    lp = np.asarray(log.laser_pose, dtype=np.float64)
    row_of = {int(v): j for j, v in enumerate(log.landmark_id.tolist())}
    d = se2.observed_points(x, z, lp) - log.landmark_xy[[row_of[int(v)] for v in lid]]
    theta = x[:, 2] + lp[2] + z[:, 1]
    number, _ = pass_sizes(log.scan_t[scan], lid, gap_s)
    order = np.lexsort((scan, number))
    number, theta, d, z, R, lid = (a[order] for a in (number, theta, d, z, R, lid))
    first = np.r_[True, number[1:] != number[:-1]]
    turn = np.abs(se2.wrap_angle(np.diff(theta, prepend=theta[:1])))
    turn[first] = 0.0
    start = np.flatnonzero(first)
    tau = np.cumsum(turn)
    tau -= np.repeat(tau[start], np.diff(np.r_[start, number.size]))
    beta = np.repeat(theta[start], np.diff(np.r_[start, number.size]))
    c, s = np.cos(beta), np.sin(beta)
    e = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    # the white covariance (range, bearing) in the pass's axes: rotated by theta_j - beta
    ca, sa = np.cos(theta - beta), np.sin(theta - beta)
    rr, ra = R[:, 0, 0], z[:, 0] ** 2 * R[:, 1, 1]
    r = np.stack([ca**2 * rr + sa**2 * ra, sa**2 * rr + ca**2 * ra], axis=1)
    return Sightings(pass_id=number, landmark=lid, tau_rad=tau, e=e, r=r)


def semivariogram(s: Sightings, edges_rad=DEFAULT_EDGES_RAD) -> Variogram:
    """The within-pass semivariogram of `s` over the bins `edges_rad` of |tau_k - tau_j|, and
    the between-pass sill (module doc)."""
    edges = np.asarray(edges_rad, dtype=np.float64)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.diff(edges) > 0) or edges[0] < 0:
        raise DataError("pass drift: bin edges must be increasing, from >= 0, at least two")
    B = edges.size - 1
    pairs, dsum = np.zeros(B), np.zeros(B)
    sq = np.zeros((B, 2))
    order = np.argsort(s.pass_id, kind="stable")
    cut = np.flatnonzero(np.diff(s.pass_id[order])) + 1
    for i in np.split(order, cut):
        if i.size < 2:
            continue
        j, k = np.triu_indices(i.size, 1)
        d = np.abs(s.tau_rad[i][k] - s.tau_rad[i][j])
        b = np.searchsorted(edges, d, side="right") - 1
        ok = (b >= 0) & (b < B)
        diff2 = (s.e[i][k] - s.e[i][j])[ok] ** 2
        pairs += np.bincount(b[ok], minlength=B)
        dsum += np.bincount(b[ok], weights=d[ok], minlength=B)
        for a in (0, 1):
            sq[:, a] += np.bincount(b[ok], weights=diff2[:, a], minlength=B)
    between, n_between = _between(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        return Variogram(
            edges_rad=edges,
            centre_rad=np.where(pairs > 0, dsum / pairs, 0.5 * (edges[:-1] + edges[1:])),
            pairs=pairs.astype(np.int64),
            gamma=0.5 * sq / pairs[:, None],
            between=between,
            between_pairs=n_between,
        )


def _between(s: Sightings) -> tuple[np.ndarray, int]:
    """0.5 E[(e_j - e_k)^2] over pairs of one landmark's sightings in different passes: all
    pairs minus the within-pass pairs, from per-group sums (no pair is formed)."""

    def sums(key):
        _, g = np.unique(key, return_inverse=True)
        n = np.bincount(g).astype(np.float64)
        s1 = np.stack([np.bincount(g, weights=s.e[:, a]) for a in (0, 1)], 1)
        s2 = np.stack([np.bincount(g, weights=s.e[:, a] ** 2) for a in (0, 1)], 1)
        # sum over pairs j < k of (e_j - e_k)^2 = n sum e^2 - (sum e)^2, per group
        return (n * (n - 1) / 2).sum(), (n[:, None] * s2 - s1**2).sum(0)

    n_all, sq_all = sums(s.landmark)
    n_in, sq_in = sums(s.pass_id)
    n = int(round(n_all - n_in))
    return (0.5 * (sq_all - sq_in) / n if n else np.full(2, np.nan)), n


def _fit_axes(c: np.ndarray, g: np.ndarray, w: np.ndarray, L: float, axes) -> tuple:
    """(r, s^2) per axis at correlation length L by non-negative weighted least squares, and
    the summed weighted squared error."""
    from scipy.optimize import nnls

    A = np.stack([np.ones_like(c), 1.0 - np.exp(-c / L)], axis=1)
    out, err = [], 0.0
    for a in axes:
        sw = np.sqrt(w[:, a])
        coef, res = nnls(A * sw[:, None], g[:, a] * sw)
        out.append(coef)
        err += res**2
    return out, err


def _best_L(c, g, w, axes) -> float:
    errs = [_fit_axes(c, g, w, L, axes)[1] for L in L_GRID]
    i = int(np.argmin(errs))
    lo, hi = math.log(L_GRID[max(i - 1, 0)]), math.log(L_GRID[min(i + 1, L_GRID.size - 1)])
    f = lambda x: _fit_axes(c, g, w, math.exp(x), axes)[1]  # noqa: E731
    k = (math.sqrt(5) - 1) / 2
    a, b = hi - k * (hi - lo), lo + k * (hi - lo)
    fa, fb = f(a), f(b)
    for _ in range(60):
        if fa < fb:
            hi, b, fb = b, a, fa
            a = hi - k * (hi - lo)
            fa = f(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + k * (hi - lo)
            fb = f(b)
    return math.exp(0.5 * (lo + hi))


def fit_drift(v: Variogram, min_pairs: int = MIN_PAIRS) -> DriftFit:
    """The Gauss-Markov fit of a semivariogram (module doc). A `DataError` when fewer than
    three bins have `min_pairs` pairs."""
    use = (v.pairs >= min_pairs) & np.all(v.gamma > 0, axis=1)
    if use.sum() < 3:
        raise DataError(
            f"pass drift: {int(use.sum())} bins with at least {min_pairs} pairs; the fit "
            "needs three (too few passes with more than one sighting)"
        )
    c, g = v.centre_rad[use], v.gamma[use]
    w = v.pairs[use][:, None] / g**2
    L = _best_L(c, g, w, (0, 1))
    (ra, sa), (rb, sb) = _fit_axes(c, g, w, L, (0, 1))[0]
    _, wsse = _fit_axes(c, g, w, L, (0, 1))
    per_axis = []
    for a in (0, 1):  # an axis with no drift of its own (s = 0 at its best L): inf
        La = _best_L(c, g, w, (a,))
        per_axis.append(La if _fit_axes(c, g, w, La, (a,))[0][0][1] > 0 else math.inf)
    sill = v.between - np.array([ra, rb])
    with np.errstate(invalid="ignore"):
        between = tuple(float(x) for x in np.where(sill >= 0, np.sqrt(np.abs(sill)), np.nan))
    return DriftFit(
        corr_rad=float(L),
        sd_m=(math.sqrt(sa), math.sqrt(sb)),
        r_eff_m2=(float(ra), float(rb)),
        corr_axis_rad=(float(per_axis[0]), float(per_axis[1])),
        bins=int(use.sum()),
        sd_between_m=between,
        wsse=float(wsse),
    )


def pass_drift(log, n_scans: int | None = None, gap_s: float = 2.0, pose=None) -> DriftFit:
    """The fit of a run's log over its first `n_scans` scans (`sightings_of`, `semivariogram`,
    `fit_drift`)."""
    return fit_drift(semivariogram(sightings_of(log, n_scans, gap_s, pose)))

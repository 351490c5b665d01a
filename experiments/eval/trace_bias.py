"""A source's systematic range error, from the trace a static trunk's sightings draw within one
pass (`trace_fit`), and the range bias (`measurement.range_bias`) that removes it, found as a
fixed point (`derive_range_bias`). No GPS enters it, and it can see what the filter's own
innovations cannot: an error that depends on where the trunk is seen from.

Projected through the filter's poses, the sightings of one pass of a landmark (its run of
sightings with no gap longer than `gap_s`) would all fall on one point if the measurements had
only white errors. A systematic error moves each sighting with the view: with u the unit line of
sight from the laser and v = u turned by +90 deg, range r and bearing beta,

    w = c + b0 u + p0 v + e beta r v + g r u  (+ white noise)

for a range offset b0 (m), an offset p0 across the line of sight (m), a bearing scale e and a
range scale g: the apparent range r exceeds the true one by b0 + g r, the apparent bearing beta
the true one by e beta + p0 / r (beta from the laser's forward axis), so the sighting moves by
(b0 + g r) u + (p0 + e beta r) v to first order. `trace_fit` fits the four shared
terms by least squares with a free centre c per pass (eliminated exactly: each pass's mean is
taken out of its rows), over the passes whose line of sight turns
by at least `min_turn_rad` (so that c and the terms can be told apart) and have at least
`min_sightings` sightings, with standard errors from the residuals.

The poses are the filter's, already pulled by the same errors (a bearing scale applied to the
data moves the fit by about half of it), so one fit under-states the error; `derive_range_bias`
therefore runs the filter again with the range bias the fit asks for, composed with the last
one (`compose_range_bias`), until the fit's range terms vanish (|b0| under `tol_m` and |g| under
`tol_per_m`), at most `max_iterations` runs. On Victoria Park's scans 1-2000 with the published
detections it converges in three runs (lab notebook, "The published detections' range error
from the trunks' traces").
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from experiments.errors import DataError
from slam import se2

__all__ = [
    "TraceFit",
    "compose_range_bias",
    "derive_range_bias",
    "sight_lines",
    "trace_fit",
    "trace_passes",
]

GAP_S = 2.0  # s: `measurement.pass_gap_s`, the filter's pass
MIN_SIGHTINGS = 6  # per pass: a centre (2) and the shared terms need more rows than that
MIN_TURN_RAD = math.radians(30.0)  # the line of sight's turn over a pass
MAX_CONDITION = 1e12  # of the fit's normal matrix (scans 1-2000 of Victoria Park: about 2e3)


@dataclass(frozen=True)
class TraceFit:
    """The shared terms of `trace_fit` (module docstring) and their standard errors (same order:
    range offset m, across offset m, bearing scale, range scale), from `passes` passes holding
    `sightings` sightings. The errors treat the rows as independent with one variance; a
    pass's shared offset makes them somewhat optimistic."""

    range_offset_m: float
    across_offset_m: float
    bearing_scale: float
    range_scale: float
    se: tuple[float, float, float, float]
    passes: int
    sightings: int


def sight_lines(log) -> tuple[np.ndarray, np.ndarray]:
    """World points of the filter's updates (through their scans' poses) and the unit lines of
    sight from the laser to them; `DataError` naming the rows when a pose or a measurement is
    not finite (a pass would otherwise drop out unseen)."""
    poses = log.pose[log.obs_scan]
    bad = ~(np.isfinite(poses).all(axis=1) & np.isfinite(log.obs_z).all(axis=1))
    if bad.any():
        raise DataError(
            f"trace fit: {int(bad.sum())} of {len(bad)} updates have a pose or a measurement "
            f"that is not finite (first at update {int(np.flatnonzero(bad)[0])})"
        )
    w = se2.observed_points(poses, log.obs_z, log.laser_pose)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    lx, ly = log.laser_pose[0], log.laser_pose[1]
    laser = np.c_[poses[:, 0] + c * lx - s * ly, poses[:, 1] + s * lx + c * ly]
    d = w - laser
    return w, d / np.linalg.norm(d, axis=1)[:, None]


def trace_passes(log, t_lo=-math.inf, t_hi=math.inf, *, gap_s=GAP_S, min_sightings=MIN_SIGHTINGS,
                 min_turn_rad=MIN_TURN_RAD) -> list[np.ndarray]:  # fmt: skip
    """The passes `trace_fit` uses, each an index array into the log's updates in time order,
    of those that start in [t_lo, t_hi) s and end before t_hi."""
    rules = {"gap_s": gap_s, "min_sightings": min_sightings, "min_turn_rad": min_turn_rad}
    return _passes(log, sight_lines(log)[1], (t_lo, t_hi), **rules)


def _passes(log, u, window, *, gap_s, min_sightings, min_turn_rad) -> list[np.ndarray]:
    """`trace_passes` with the updates' unit lines of sight u given."""
    t_lo, t_hi = window
    t = log.scan_t[log.obs_scan]
    out = []
    for landmark in np.unique(log.obs_landmark):
        m = np.flatnonzero(log.obs_landmark == landmark)
        m = m[np.argsort(t[m], kind="stable")]
        for part in np.split(m, np.flatnonzero(np.diff(t[m]) > gap_s) + 1):
            if len(part) < min_sightings or not (t_lo <= t[part[0]] and t[part[-1]] < t_hi):
                continue
            turn = np.ptp(np.unwrap(np.arctan2(u[part, 1], u[part, 0])))
            if turn >= min_turn_rad:
                out.append(part)
    return out


def trace_fit(log, t_lo=-math.inf, t_hi=math.inf, **pass_rules) -> TraceFit:
    """Fit the shared terms over the passes of `trace_passes(log, t_lo, t_hi, **pass_rules)`;
    `DataError` when there are too few passes to fit them."""
    w_all, u_all = sight_lines(log)
    rules = {"gap_s": GAP_S, "min_sightings": MIN_SIGHTINGS, "min_turn_rad": MIN_TURN_RAD}
    passes = _passes(log, u_all, (t_lo, t_hi), **(rules | pass_rules))
    n = sum(len(p) for p in passes)
    if len(passes) < 2 or 2 * n < 2 * len(passes) + 4 + 1:
        raise DataError(
            f"trace fit: {len(passes)} passes of {n} sightings in [{t_lo}, {t_hi}) s; it needs "
            "at least 2 passes whose line of sight turns enough"
        )
    idx = np.concatenate(passes)
    w, u, z = w_all[idx], u_all[idx], log.obs_z[idx]
    v = np.c_[-u[:, 1], u[:, 0]]
    terms = np.stack([u, v, (z[:, 1] * z[:, 0])[:, None] * v, z[:, :1] * u], axis=-1)  # n,2,4
    which = np.repeat(np.arange(len(passes)), [len(p) for p in passes])
    sizes = np.array([len(p) for p in passes], dtype=float)
    X, y = _within(terms, which, sizes), _within(w, which, sizes)
    X, y = X.reshape(2 * n, 4), y.ravel()  # each pass's centre eliminated (its mean removed)
    normal = X.T @ X
    if not np.linalg.cond(normal) < MAX_CONDITION:
        raise DataError(
            f"trace fit: the {len(passes)} passes cannot tell the four terms apart (normal "
            f"matrix condition {np.linalg.cond(normal):.3g}): the range or the view must vary "
            "within the passes"
        )
    shared = np.linalg.solve(normal, X.T @ y)
    e = y - X @ shared
    dof = max(2 * n - 2 * len(passes) - 4, 1)
    se = np.sqrt(np.diag(np.linalg.inv(normal)) * float(e @ e) / dof)
    return TraceFit(*map(float, shared), tuple(map(float, se)), len(passes), n)  # type: ignore[arg-type]


def _within(a: np.ndarray, which: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """`a` (n, ...) less the mean of its pass (the least-squares fit of a free centre per pass
    is the fit of these differences)."""
    flat = a.reshape(len(a), -1)
    sums = np.zeros((len(sizes), flat.shape[1]))
    np.add.at(sums, which, flat)
    return (flat - (sums / sizes[:, None])[which]).reshape(a.shape)


def compose_range_bias(bias: tuple[float, float], fit: TraceFit) -> tuple[float, float]:
    """The range bias (a, b) of `measurement.range_bias` (r -> r - (a + b r)) that removes the
    fit's range offset and scale from ranges already corrected by `bias`: the corrected range
    r' = (1 - b) r - a exceeds the true one by b0 + g r', so r_true = (1 - g) r' - b0 =
    r - (a_new + b_new r) with a_new = (1 - g) a + b0 and b_new = 1 - (1 - g)(1 - b)."""
    a, b = bias
    b0, g = fit.range_offset_m, fit.range_scale
    return (1.0 - g) * a + b0, 1.0 - (1.0 - g) * (1.0 - b)


def derive_range_bias(run: Callable[[tuple[float, float]], object], *, t_lo=-math.inf,
                      t_hi=math.inf, tol_m=0.002, tol_per_m=2e-4, max_iterations=6,
                      progress=None) -> tuple[tuple[float, float], list[tuple]]:  # fmt: skip
    """The fixed point of (run the filter with a range bias, fit the trace, compose): `run`
    maps a range bias to the run's log. Returns the bias and the history, one (bias, fit) per
    run; `DataError` when it has not converged within `max_iterations` runs."""
    if not (isinstance(max_iterations, int) and max_iterations >= 1):
        raise ValueError(
            f"derive_range_bias: max_iterations must be an int >= 1, got {max_iterations!r}"
        )
    bias, history = (0.0, 0.0), []
    for i in range(max_iterations):
        fit = trace_fit(run(bias), t_lo, t_hi)
        history.append((bias, fit))
        if progress is not None:
            progress(i + 1, max_iterations)
        if abs(fit.range_offset_m) < tol_m and abs(fit.range_scale) < tol_per_m:
            return bias, history
        bias = compose_range_bias(bias, fit)
    (a, b), fit = history[-1]
    raise DataError(
        f"range bias: the trace fit did not settle in {max_iterations} runs (the last ran with "
        f"a {a:+.4f} m, b {b:+.6f} per m and left b0 {fit.range_offset_m:+.4f} m, g "
        f"{fit.range_scale:+.6f}; the next would be a {bias[0]:+.4f} m, b {bias[1]:+.6f})"
    )

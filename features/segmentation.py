"""Scan segmentation by an EKF with Adams' planar range model (paper section 2.1).

The state is x = [d_k, d_(k-1)] (newest range first). Along a planar surface successive ranges obey
eq. (1), d_(k+1) = d_k d_(k-1) / (2 d_(k-1) cos(gamma) - d_k), which the EKF uses as its process
model (eq. 2) with observation z = [1 0] x + w (eq. 3). A range whose normalised innovation
squared exceeds the gate delta (eq. 4) ends the segment; the filter restarts from that beam.

Two implementations of the same per-beam loop:
- `segment_kernel`: the numba kernel used in production (scalar, unrolled);
- `segment_kernel_numpy`: a plain numpy twin written with 2x2 matrices, straight from the
  equations, used as the test oracle (`segment_ranges(..., kernel="numpy")`).

Conventions shared by both
- No-return beams (NaN) end a segment and are never part of one.
- Initialisation from the first two ranges: x = [d_2, d_1], P = sigma_r^2 I (docs/method.md
  section 2).
- Degenerate (almost parallel) case, which the paper says to reject: when the predicted range
  grows by more than `max_growth` relative to the last range (equivalently the surface would be
  seen at more than `max_incidence_rad` from its normal, or D <= 0), the measurement is rejected
  and treated as a break.
- On a break at beam i the segment ends at beam i-1 and the filter restarts from beams (i, i+1).
  If the break comes on the segment's first prediction (only two beams so far), the two initial
  beams cannot both be trusted: the older one is left as a one-beam segment and the filter
  restarts from (i-1, i). This keeps a lone mixed pixel at a depth jump from swallowing the first
  beam of the next surface.
- Per-beam outputs: `innovation_m[i]` and `innovation_var_m2[i]` are the innovation and its
  variance when beam i was validated by the filter, NaN otherwise (first two beams of a segment,
  breaks, no returns).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from features.errors import FeaturesError

__all__ = [
    "END_NO_RETURN",
    "END_GATE",
    "END_DEGENERATE",
    "END_SCAN",
    "max_growth_ratio",
    "planar_predict",
    "planar_jacobian",
    "segment_ranges",
    "segment_kernel",
    "segment_kernel_numpy",
]

# Why a segment ended (the reason is about the beam after its last one).
END_NO_RETURN, END_GATE, END_DEGENERATE, END_SCAN = 0, 1, 2, 3


def max_growth_ratio(gamma_rad: float, max_incidence_rad: float) -> float:
    """Largest ratio d_(k+1)/d_k a plane seen at <= max_incidence_rad from its normal gives."""
    a = max_incidence_rad
    if not 0.0 < a + gamma_rad < math.pi / 2:
        raise FeaturesError(
            f"max_incidence_rad: must be in (0, pi/2 - gamma), got {max_incidence_rad!r}"
        )
    return math.cos(a) / math.cos(a + gamma_rad)


def planar_predict(x: np.ndarray, cos_gamma: float) -> np.ndarray:
    """eq. (2): f(x) = [x1 x2 / (2 x2 cos(gamma) - x1), x1] for x = [d_k, d_(k-1)]."""
    x1, x2 = x[0], x[1]
    return np.array([x1 * x2 / (2.0 * x2 * cos_gamma - x1), x1])


def planar_jacobian(x: np.ndarray, cos_gamma: float) -> np.ndarray:
    """df/dx of eq. (2): [[2 x2^2 cos(gamma) / D^2, -x1^2 / D^2], [1, 0]], D = 2 x2 cos - x1."""
    x1, x2 = x[0], x[1]
    D = 2.0 * x2 * cos_gamma - x1
    return np.array([[2.0 * x2 * x2 * cos_gamma / (D * D), -x1 * x1 / (D * D)], [1.0, 0.0]])


@njit(cache=True, nogil=True, error_model="numpy")
def segment_kernel(ranges, cos_gamma, sigma_r, q, gate, max_growth):
    """Numba kernel; see `segment_ranges`. Returns (bounds (S, 2), end_reason (S,), innov, s)."""
    n = ranges.shape[0]
    r2 = sigma_r * sigma_r
    bounds = np.empty((n, 2), np.int64)
    reason = np.empty(n, np.int64)
    innov = np.full(n, np.nan)
    svar = np.full(n, np.nan)
    ns = 0
    start = -1  # first beam of the open segment, -1 when none is open
    count = 0  # beams in the open segment
    x1 = 0.0
    x2 = 0.0
    p11 = 0.0
    p12 = 0.0
    p22 = 0.0
    i = 0
    while i < n:  # bounded: every pass ends with i += 1, n passes
        z = ranges[i]
        if not (z == z):  # NaN: no return ends the open segment
            if start >= 0:
                bounds[ns, 0] = start
                bounds[ns, 1] = i - 1
                reason[ns] = END_NO_RETURN
                ns += 1
                start = -1
            i += 1
            continue
        if start < 0:
            start = i
            count = 1
            i += 1
            continue
        if count == 1:
            x1 = z
            x2 = ranges[i - 1]
            p11 = r2
            p12 = 0.0
            p22 = r2
            count = 2
            i += 1
            continue
        # predict, eq. (2)
        D = 2.0 * x2 * cos_gamma - x1
        why = -1
        if D <= 0.0 or x2 > max_growth * D or D * D == 0.0:
            why = END_DEGENERATE  # almost parallel: reject the measurement
        else:
            pred = x1 * x2 / D
            f11 = 2.0 * x2 * x2 * cos_gamma / (D * D)
            f12 = -x1 * x1 / (D * D)
            # P- = F P F^T + Q, Q = diag(q, 0); F = [[f11, f12], [1, 0]]
            a11 = f11 * p11 + f12 * p12
            a12 = f11 * p12 + f12 * p22
            m11 = a11 * f11 + a12 * f12 + q
            m12 = a11
            m22 = p11
            s = m11 + r2  # eq. (3): H = [1 0]
            nu = z - pred
            if nu * nu / s > gate:  # eq. (4): validation gate
                why = END_GATE
            else:
                k1 = m11 / s
                k2 = m12 / s
                x2 = x1
                x1 = pred + k1 * nu
                x2 = x2 + k2 * nu
                # Joseph form: (I - K H) M (I - K H)^T + K R K^T
                g = 1.0 - k1
                p11 = g * g * m11 + k1 * k1 * r2
                p12 = g * (m12 - k2 * m11) + k1 * k2 * r2
                p22 = m22 - 2.0 * k2 * m12 + k2 * k2 * m11 + k2 * k2 * r2
                innov[i] = nu
                svar[i] = s
                count += 1
                i += 1
                continue
        # break before beam i
        if count == 2:
            bounds[ns, 0] = start
            bounds[ns, 1] = start
            reason[ns] = why
            ns += 1
            start = i - 1
            x1 = z
            x2 = ranges[i - 1]
            p11 = r2
            p12 = 0.0
            p22 = r2
            i += 1
        else:
            bounds[ns, 0] = start
            bounds[ns, 1] = i - 1
            reason[ns] = why
            ns += 1
            start = i
            count = 1
            i += 1
    if start >= 0:
        bounds[ns, 0] = start
        bounds[ns, 1] = n - 1
        reason[ns] = END_SCAN
        ns += 1
    return bounds[:ns], reason[:ns], innov, svar


def _check(ranges_m, gamma_rad, sigma_r_m, q_m2, gate) -> np.ndarray:
    """The ranges as float64 with NaN for no return, after checking the filter's parameters."""
    r = np.asarray(ranges_m, dtype=np.float64)
    if r.ndim != 1:
        raise FeaturesError(f"ranges_m: expected shape (B,), got {r.shape}")
    for name, v in (("gamma_rad", gamma_rad), ("sigma_r_m", sigma_r_m), ("gate", gate)):
        if not (math.isfinite(v) and v > 0):
            raise FeaturesError(f"{name}: must be a finite positive number, got {v!r}")
    if not (math.isfinite(q_m2) and q_m2 >= 0):
        raise FeaturesError(f"q_m2: must be finite and >= 0, got {q_m2!r}")
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(r) & (r > 0), r, np.nan)


def segment_ranges(
    ranges_m: np.ndarray,
    gamma_rad: float,
    sigma_r_m: float = 0.02,
    q_m2: float = 1e-4,
    gate: float = 6.63,
    max_incidence_rad: float = math.radians(85.0),
    *,
    kernel: str = "numba",
):
    """Segment one scan's ranges with the planar-model EKF.

    ranges_m: (B,) metres, NaN (or any non-positive / non-finite value) = no return.
    gamma_rad: angle between successive beams. sigma_r_m: range noise. q_m2: process noise Q
    (paper: 1e-4). gate: delta of eq. (4) (paper: 6.63, chi-square 1 dof at 0.99).
    max_incidence_rad: degenerate-case limit (see module doc).
    kernel: "numba" (`segment_kernel`, production) or "numpy" (`segment_kernel_numpy`, the
    test oracle).

    Returns (bounds (S, 2) int inclusive [first, last] beams, end_reason (S,) int,
    innovation_m (B,), innovation_var_m2 (B,)).
    """
    kernels = {"numba": segment_kernel, "numpy": segment_kernel_numpy}
    if kernel not in kernels:
        raise FeaturesError(f"kernel: expected 'numba' or 'numpy', got {kernel!r}")
    r = _check(ranges_m, gamma_rad, sigma_r_m, q_m2, gate)
    growth = max_growth_ratio(gamma_rad, max_incidence_rad)
    # the kernels' public signature (ranges, cos_gamma, sigma_r, q, gate, max_growth)
    return kernels[kernel](r, math.cos(gamma_rad), sigma_r_m, q_m2, gate, growth)


def segment_kernel_numpy(r, c, sigma_r_m, q_m2, gate, growth):
    """The plain-numpy twin of `segment_kernel` (same arguments and outputs), written with
    2x2 matrices straight from the equations."""
    R = sigma_r_m**2
    Q = np.array([[q_m2, 0.0], [0.0, 0.0]])
    H = np.array([[1.0, 0.0]])
    n = r.shape[0]
    innov = np.full(n, np.nan)
    svar = np.full(n, np.nan)
    bounds: list[tuple[int, int]] = []
    reasons: list[int] = []
    seg: list[int] = []  # beams of the open segment
    x = np.zeros(2)
    P = np.eye(2)

    def restart(i_old: int, i_new: int):
        return np.array([r[i_new], r[i_old]]), R * np.eye(2)

    for i in range(n):
        if np.isnan(r[i]):
            if seg:
                bounds.append((seg[0], seg[-1]))
                reasons.append(END_NO_RETURN)
                seg = []
            continue
        if not seg:
            seg = [i]
            continue
        if len(seg) == 1:
            x, P = restart(i - 1, i)
            seg.append(i)
            continue
        D = 2.0 * x[1] * c - x[0]
        why = None
        if D <= 0.0 or x[1] / D > growth or D * D == 0.0:
            why = END_DEGENERATE
        else:
            x_pred = planar_predict(x, c)
            F = planar_jacobian(x, c)
            P_pred = F @ P @ F.T + Q
            S = (H @ P_pred @ H.T)[0, 0] + R
            nu = r[i] - x_pred[0]
            if nu * nu / S > gate:  # eq. (4)
                why = END_GATE
            else:
                K = P_pred @ H.T / S
                x = x_pred + K[:, 0] * nu
                I_KH = np.eye(2) - K @ H
                P = I_KH @ P_pred @ I_KH.T + K @ K.T * R
                innov[i] = nu
                svar[i] = S
                seg.append(i)
                continue
        if len(seg) == 2:
            bounds.append((seg[0], seg[0]))
            reasons.append(why)
            seg = [seg[1], i]
            x, P = restart(i - 1, i)
        else:
            bounds.append((seg[0], seg[-1]))
            reasons.append(why)
            seg = [i]
    if seg:
        bounds.append((seg[0], seg[-1]))
        reasons.append(END_SCAN)
    b = np.array(bounds, dtype=np.int64).reshape(-1, 2)
    return b, np.array(reasons, dtype=np.int64), innov, svar

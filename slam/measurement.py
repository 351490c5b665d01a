"""Circles as range-bearing measurements of their centres, with a noise model per extractor.

Two noise models (`SlamConfig.measurement_noise`):
- "fit": the circle fit's own covariance of the centre (the `geometric` extractor computes one),
  carried from the laser's x-y frame to range and bearing to first order (`polar_cov_from_xy`),
  plus an optional floor for model error the fit cannot see;
- "constant": sigma_range = a + b range, sigma_bearing^2 = c^2 + (t / range)^2, with per-method
  values (`SlamConfig.measurement.constant_noise`; built in, one model for every extractor,
  `slam.config.DEFAULT_CONSTANT_NOISE`) for extractors that give no covariance.
A known mean range error of an extractor (`SlamConfig.measurement.range_bias`; none built in,
the `cycab` preset's are the simulated tree park's) is subtracted from its ranges before either
model is applied.

A trunk's centre offset shared by the sightings of one pass (`measurement.pass_offset_sd_m`):
`pass_variance` (the filter's k-th sighting of a pass, and a batch's n sightings) and
`pass_inflation` (what it adds to a measurement's covariance, per axis of the line of sight).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "MeasurementModel",
    "NoiseModel",
    "constant_noise",
    "line_of_sight_cov",
    "measurements_from_features",
    "pass_inflation",
    "pass_sizes",
    "pass_variance",
    "polar_cov_from_xy",
]


class NoiseModel(NamedTuple):
    """The constant measurement-noise model of an extractor (metres, radians):
    sigma_range = range_sigma_m + range_sigma_per_m * range,
    sigma_bearing^2 = bearing_sigma_rad^2 + (cross_range_sigma_m / range)^2."""

    range_sigma_m: float
    range_sigma_per_m: float
    bearing_sigma_rad: float
    cross_range_sigma_m: float


@dataclass(frozen=True)
class MeasurementModel:
    """The measurement model of one source of circles, resolved from the configuration
    (`slam.config.MeasurementConfig.model_for`): every source (extracted features, a sequence's
    detections, precomputed features) goes through `measure`.

    kind: "fit" (the circle's own covariance plus `floor` (range m, bearing rad) sigmas in
        quadrature) or "constant" (`constant_noise` of `constant`).
    range_bias: (a_m, b_per_m), the source's known mean range error a + b r, subtracted from
        every range r.
    """

    kind: str
    constant: NoiseModel
    floor: tuple[float, float] = (0.0, 0.0)
    range_bias: tuple[float, float] = (0.0, 0.0)

    def measure(self, z: np.ndarray, cov: np.ndarray | None = None):
        """Measurements z (m, 2) [range m, bearing rad] with their covariance cov (m, 2, 2) as
        the source gives it (None: none) -> (z less the range bias, R (m, 2, 2))."""
        z = np.array(z, dtype=np.float64).reshape(-1, 2)
        z[:, 0] -= self.range_bias[0] + self.range_bias[1] * z[:, 0]
        if self.kind == "fit":
            if cov is None:
                raise ValueError("measurement noise 'fit' needs the source's covariance")
            return z, cov + np.diag([self.floor[0] ** 2, self.floor[1] ** 2])
        return z, constant_noise(z, self.constant)

    def from_features(self, features) -> tuple[np.ndarray, np.ndarray]:
        """Range-bearing measurements (C, 2) of the circle centres of `features` (laser frame)
        and their covariances (C, 2, 2)."""
        c = np.asarray(features.circle_params, dtype=np.float64).reshape(-1, 3)
        if self.kind == "fit":
            z, cov = polar_cov_from_xy(c[:, :2], np.asarray(features.circle_cov)[:, :2, :2])
            return self.measure(z, cov)
        z, _ = polar_cov_from_xy(c[:, :2], np.zeros((c.shape[0], 2, 2)))
        return self.measure(z)


def measurements_from_features(
    features,
    noise: tuple[str, tuple[float, float, float, float]],
    floor: tuple[float, float] = (0.0, 0.0),
    range_bias: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray]:
    """Range-bearing measurements (C, 2) of the circle centres and their covariances (C, 2, 2)
    under noise (kind, NoiseModel): `MeasurementModel(kind, model, floor, range_bias)`'s."""
    kind, model = noise  # ("fit", None): the fit's covariance needs no constant model
    constant = NoiseModel(0.0, 0.0, 0.0, 0.0) if model is None else NoiseModel(*model)
    return MeasurementModel(kind, constant, floor, range_bias).from_features(features)


def constant_noise(z: np.ndarray, model) -> np.ndarray:
    """(m, 2, 2) diagonal covariances of measurements z (m, 2) [range, bearing] under the
    constant model (range_sigma_m, range_sigma_per_m, bearing_sigma_rad, cross_range_sigma_m)."""
    s_r, s_rm, s_b, s_t = model
    R = np.zeros((z.shape[0], 2, 2))
    R[:, 0, 0] = (s_r + s_rm * z[:, 0]) ** 2
    with np.errstate(divide="ignore"):
        R[:, 1, 1] = s_b**2 + (s_t / z[:, 0]) ** 2
    return R


def polar_cov_from_xy(center_xy: np.ndarray, cov_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A laser-frame point (k, 2) with covariance (k, 2, 2) as [range, bearing] and its cov."""
    c = np.asarray(center_xy, dtype=np.float64).reshape(-1, 2)
    C = np.asarray(cov_xy, dtype=np.float64).reshape(-1, 2, 2)
    r2 = c[:, 0] ** 2 + c[:, 1] ** 2
    r = np.sqrt(r2)
    z = np.stack([r, np.arctan2(c[:, 1], c[:, 0])], axis=1)
    J = np.empty((c.shape[0], 2, 2))
    J[:, 0, 0] = c[:, 0] / r
    J[:, 0, 1] = c[:, 1] / r
    J[:, 1, 0] = -c[:, 1] / r2
    J[:, 1, 1] = c[:, 0] / r2
    Rz = J @ C @ np.transpose(J, (0, 2, 1))
    return z, 0.5 * (Rz + np.transpose(Rz, (0, 2, 1)))


def pass_variance(r, k, s, batch: bool = False):
    """The variance of one axis of a sighting whose white variance is r (m^2) when the n
    sightings of a pass share an offset b ~ N(0, s^2) on that axis (s in m): the pass then
    carries 1 / (r/n + s^2) of information, not n / r.

    Sequential (the filter, `batch` False): the k-th sighting of the pass (k = 1, 2, ...) gets
        v_k = (r + k s^2)(r + (k - 1) s^2) / r (k = 1: r + s^2), so that the first k sightings
        together carry sum 1/v_j = k / (r + k s^2), the information of k sightings that share
        the offset (telescoping: 1/v_j = j/(r + j s^2) - (j - 1)/(r + (j - 1) s^2)).
    Batch (the smoother, `batch` True): each of the n = k sightings of a pass gets r + n s^2.
    Arrays broadcast; s = 0 returns r."""
    return np.asarray(r, dtype=np.float64) + _pass_extra(r, k, s, batch)


def _pass_extra(r, k, s, batch: bool):
    """pass_variance - r, computed so that s = 0 adds exactly 0: batch n s^2; sequential
    (2k - 1) s^2 + k (k - 1) s^4 / r (v_k expanded)."""
    r = np.asarray(r, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    s2 = float(s) ** 2
    if batch:
        return k * s2
    return (2.0 * k - 1.0) * s2 + k * (k - 1.0) * s2 * s2 / r


def line_of_sight_cov(bearing_rad, sd) -> np.ndarray:
    """(k, 2, 2) world-frame covariances of offsets with standard deviations sd = (along,
    across) in m along and across lines of sight at world bearings bearing_rad (k,):
    Rot(b) diag(sd_along^2, sd_across^2) Rot(b)^T, as u u^T sd_along^2 + v v^T sd_across^2
    (u along the line, v across it; exactly symmetric). The pass offset's covariance in the
    filter (`slam.pass_state`) and the smoother (`slam.smoother.pass_offset_cov`)."""
    b = np.asarray(bearing_rad, dtype=np.float64).reshape(-1)
    u = np.stack([np.cos(b), np.sin(b)], axis=1)  # along the line of sight
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)  # across it
    return sd[0] ** 2 * np.einsum("ki,kj->kij", u, u) + sd[1] ** 2 * np.einsum("ki,kj->kij", v, v)


def pass_inflation(z, R, k, sd, batch: bool = False) -> np.ndarray:
    """Covariances R (m, 2, 2) of range-bearing measurements z (m, 2) with the pass offset
    added: sd = (range, across) standard deviations (m); k (m,) each measurement's index in its
    pass (`batch`: its pass's size). Range axis: r = R_rr; across the line of sight: r = range^2
    R_bb (the bearing variance in metres), its extra variance divided back by range^2. The
    extra is added to the diagonal, so a correlation of R is kept. Returns a new array."""
    z = np.asarray(z, dtype=np.float64).reshape(-1, 2)
    out = np.array(R, dtype=np.float64).reshape(-1, 2, 2)
    rng2 = z[:, 0] ** 2
    r_range = out[:, 0, 0]
    r_across = rng2 * out[:, 1, 1]
    out[:, 0, 0] += _pass_extra(r_range, k, sd[0], batch)
    out[:, 1, 1] += _pass_extra(r_across, k, sd[1], batch) / rng2
    return out


def pass_sizes(t_s, landmark, gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The passes of sightings at times t_s (m,) of landmarks `landmark` (m,): a landmark's
    pass ends after more than `gap_s` without a sighting of it (the filter's rule,
    `slam.history.RunHistory.pass_index`). Returns (pass number of each sighting (m,), numbered
    0.. over all landmarks, and the size of its pass (m,))."""
    t = np.asarray(t_s, dtype=np.float64).reshape(-1)
    lm = np.asarray(landmark, dtype=np.int64).reshape(-1)
    order = np.lexsort((t, lm))
    ts, ls = t[order], lm[order]
    new = np.ones(t.size, bool)
    new[1:] = (ls[1:] != ls[:-1]) | (np.diff(ts) > gap_s)
    number = np.cumsum(new) - 1
    size = np.bincount(number)[number] if t.size else np.zeros(0, np.int64)
    out_n, out_size = np.empty(t.size, np.int64), np.empty(t.size, np.int64)
    out_n[order], out_size[order] = number, size
    return out_n, out_size

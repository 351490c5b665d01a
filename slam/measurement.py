"""Circles as range-bearing measurements of their centres, with a noise model per extractor.

Two noise models (`SlamConfig.measurement_noise`):
- "fit": the circle fit's own covariance of the centre (the `geometric` extractor computes one),
  carried from the laser's x-y frame to range and bearing to first order (`polar_cov_from_xy`),
  plus an optional floor for model error the fit cannot see;
- "constant": sigma_range = a + b range, sigma_bearing^2 = c^2 + (t / range)^2, with per-method
  values (`DEFAULT_CONSTANT_NOISE`) for extractors that give no covariance.
A known mean range error of an extractor (`DEFAULT_RANGE_BIAS`, `SlamConfig.range_bias`) is
subtracted from its ranges before either model is applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = [
    "DEFAULT_CONSTANT_NOISE",
    "DEFAULT_FIT_FLOOR",
    "DEFAULT_RANGE_BIAS",
    "MeasurementModel",
    "NoiseModel",
    "constant_noise",
    "measurements_from_features",
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


# The "constant" measurement noise model of each extractor: configured constants, not a fit:
#   sigma_range = range_sigma_m + range_sigma_per_m * range,
#   sigma_bearing^2 = bearing_sigma_rad^2 + (cross_range_sigma_m / range)^2.
# Values: maximum-likelihood fits of this model to the range and bearing errors of the centres
# of the circles found on trunks in the simulated tree park (LMS200, 1 cm range noise, 1 cm
# quantisation; `trunkslam reproduce noise-calibration`, seeds 1000-1003, apart from the
# experiment's, each run's path varied as in experiment 2), rounded up to two digits. Fitted
# (a, b, c, t): paper (0.0120, 0.00085, 0, 0.0081), geometric (0.0081, 0.0013, 0, 0.0078),
# bailey (0.0098, 0.0014, 0.0019, 0.0022). The fitted extractors' centres are off by under 1 cm
# across the beam (the bearing error falls as 1/range: c fits to 0); the Bailey detector's
# bearing is quantised by the beams (about 0.1 deg whatever the range). The paper's fit also has
# a mean range error of -4.6 mm (Kasa's bias toward the sensor), which a zero-mean model cannot
# represent (`DEFAULT_RANGE_BIAS`).
# "other" (any other source of circles): the Zaragoza SLAM-school model of the Victoria Park
# detections, 0.05 m + 1% of the range and 0.5 deg (BAILEY_DETECTOR.md section 4).
DEFAULT_CONSTANT_NOISE: dict[str, NoiseModel] = {
    "paper": NoiseModel(0.013, 0.00085, 0.0, 0.0081),
    "geometric": NoiseModel(0.0082, 0.0014, 0.0, 0.0078),
    "bailey": NoiseModel(0.0098, 0.0014, 0.0019, 0.0022),
    "other": NoiseModel(0.05, 0.01, math.radians(0.5), 0.0),
}

# Mean range error of each extractor's centres as a function of range, bias(r) = a + b r
# (a in m, b in m per m of range), subtracted from its ranges: the line through the range errors
# of the circles found on trunks in the calibration runs (noise-calibration, seeds 1000-1003,
# never the experiment's) by maximum likelihood under the filter's own sigmas (least squares
# weighted by 1 / sigma^2; `experiments.paper.calibration.range_bias_line`), rounded to 0.1 mm
# and 0.01 mm per m. paper (-0.0076, 0.00010): its Gauss-Newton fit pulls the centre toward the
# sensor (mean -4.6 mm, -0.42 of the sigma of its own covariance, which the filter uses for it);
# bailey (-0.0097, 0.00062): its radius from the angular width is too small (mean -2.7 mm, -0.16
# sigma); geometric (-0.0008, -0.00021): +0.9 mm on average, but -0.10 of the sigma the filter
# gives each fit, so biased where the fit is precise (an unweighted line made its NEES worse).
# A bias that every tree shares is not noise: a filter that treats scans as independent averages
# it into the pose with ever-growing confidence (NEES above its bounds). Applied to every circle
# of that method (extracted, or a sequence's detections); the Victoria Park preset sets them to 0
# (the simulated sensor's biases say nothing of the real one).
DEFAULT_RANGE_BIAS: dict[str, tuple[float, float]] = {
    "paper": (-0.0076, 0.0001),
    "geometric": (-0.0008, -0.00021),
    "bailey": (-0.0097, 0.00062),
}

# Floors (range m, bearing rad) added in quadrature to a fit's own covariance ("fit" noise):
# maximum-likelihood fit of R_fit + diag(f_r^2, f_b^2) to the `geometric` centres' errors in the
# calibration runs (seeds 1000-1003): 6.29 mm and 0.092 mrad (rounded up to 2 digits). The fit's
# covariance assumes independent Gaussian range noise; the 1 cm quantisation and the mixed
# returns at the trunk's edges are neither, and the most precise fits (many beams, close
# trees: the ones that steer the filter) were the most over-confident (range sigma under 10 mm:
# errors 1.37-1.54 times their stated variance). NIS per dof of the calibration circles: 1.17
# under the fit's covariance, 0.93 with the floors.
DEFAULT_FIT_FLOOR: tuple[float, float] = (0.0063, 0.000093)


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

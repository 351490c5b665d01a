"""`SlamConfig`: every setting of a `slam.run`, with the experiments' values as defaults."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

from slam.errors import SlamError
from slam.mapping import MapPolicy
from slam.measurement import DEFAULT_CONSTANT_NOISE
from slam.vehicle import OdometryNoise

__all__ = ["SlamConfig"]


@dataclass(frozen=True)
class SlamConfig:
    """Parameters of the run; defaults are the ones the experiments use.

    odometry_noise: sigma of each odometry sample's speed and steering readings.
    measurement_noise: "auto" (fit covariance for `geometric` features, constant otherwise),
        "fit" or "constant".
    range_sigma_m, range_sigma_per_m, bearing_sigma_rad, cross_range_sigma_m: the constant
        noise model (see `DEFAULT_CONSTANT_NOISE`); None = the feature method's default.
    fit_floor_range_m, fit_floor_bearing_rad: added in quadrature to the fit's noise (model
        error the fit cannot see; 0 in simulation where trunks are true circles).
    gate_prob: chi-square probability of the association gates (passed to `associate`). 0.999
        rather than association's 0.99: in the tree park a 3-sigma odometry heading step
        (one in about a thousand scans) pushed both visible trees out of a 0.99 gate; they were
        re-mapped as new landmarks and the run never recovered (2 of 50 runs, pose errors of
        10-18 cm). Inside the gate the choice is IHGR's likelihood costs, not the gate.
    new_feature_gate_prob: an unassociated measurement starts a tentative feature only when it
        lies outside this (wider) gate of every landmark and tentative feature in view;
        between the two gates it is ignored (status AMBIGUOUS), so a measurement of a mapped
        tree that just failed its gate does not become a duplicate landmark.
    association_params: extra keyword arguments of `association.associate`.
    map_policy: tentative features (`slam.mapping.MapPolicy`).
    initial_pose_sigma: (sigma_x_m, sigma_y_m, sigma_theta_rad) of the start pose when it comes
        from the truth (0: the map's frame is the start pose).
    gps_sigma_m, initial_heading_sigma_rad: start uncertainty when the start is a GPS fix.
    max_odometry_gap_s: a longer stretch without odometry inside the run is an error.
    max_feature_range_m: circles farther away are not used.
    view_margin_m, view_margin_rad: landmarks this far outside the laser's range and field of
        view are still offered to the association.
    """

    odometry_noise: OdometryNoise = field(default_factory=OdometryNoise)
    measurement_noise: str = "auto"
    range_sigma_m: float | None = None
    range_sigma_per_m: float | None = None
    bearing_sigma_rad: float | None = None
    cross_range_sigma_m: float | None = None
    fit_floor_range_m: float = 0.0
    fit_floor_bearing_rad: float = 0.0
    gate_prob: float = 0.999
    new_feature_gate_prob: float = 0.9999
    association_params: dict = field(default_factory=dict)
    map_policy: MapPolicy = field(default_factory=MapPolicy)
    initial_pose_sigma: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gps_sigma_m: float = 1.0
    initial_heading_sigma_rad: float = math.radians(5.0)
    max_odometry_gap_s: float = 1.0
    max_feature_range_m: float = math.inf
    view_margin_m: float = 2.0
    view_margin_rad: float = math.radians(10.0)

    def __post_init__(self) -> None:
        if self.measurement_noise not in ("auto", "fit", "constant"):
            raise SlamError(
                f"SlamConfig.measurement_noise: expected 'auto', 'fit' or 'constant', got "
                f"{self.measurement_noise!r}"
            )
        for name in ("gate_prob", "new_feature_gate_prob"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise SlamError(f"SlamConfig.{name}: must be in (0, 1), got {v!r}")
        for name in (
            "range_sigma_m",
            "range_sigma_per_m",
            "bearing_sigma_rad",
            "cross_range_sigma_m",
        ):
            v = getattr(self, name)
            if v is not None and not (0 <= v < math.inf):
                raise SlamError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        for name in (
            "fit_floor_range_m",
            "fit_floor_bearing_rad",
            "gps_sigma_m",
            "initial_heading_sigma_rad",
            "view_margin_m",
            "view_margin_rad",
        ):
            v = getattr(self, name)
            if not (0 <= v < math.inf):
                raise SlamError(f"SlamConfig.{name}: must be finite and >= 0, got {v!r}")
        if not self.max_odometry_gap_s > 0:
            raise SlamError("SlamConfig.max_odometry_gap_s: must be > 0")
        if len(self.initial_pose_sigma) != 3 or min(self.initial_pose_sigma) < 0:
            raise SlamError("SlamConfig.initial_pose_sigma: expected three sigmas >= 0")

    def noise_for(self, method: str) -> tuple[str, tuple[float, float, float, float]]:
        """("fit" | "constant", (range_sigma_m, range_sigma_per_m, bearing_sigma_rad,
        cross_range_sigma_m)) for a feature method."""
        kind = self.measurement_noise
        if kind == "auto":
            kind = "fit" if method == "geometric" else "constant"
        base = DEFAULT_CONSTANT_NOISE.get(method, DEFAULT_CONSTANT_NOISE["other"])
        given = (
            self.range_sigma_m,
            self.range_sigma_per_m,
            self.bearing_sigma_rad,
            self.cross_range_sigma_m,
        )
        model = tuple(float(b if g is None else g) for b, g in zip(base, given))
        if kind == "constant" and (model[0] + model[1] <= 0 or model[2] + model[3] <= 0):
            raise SlamError(f"SlamConfig: the constant noise model {model} is zero")
        return kind, model  # type: ignore[return-value]

    def to_dict(self) -> dict:
        return asdict(self)

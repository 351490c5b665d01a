"""Victoria Park: the ute's noise and laser mounting, derived from scans 1-2000 only.

`trunkslam reproduce victoria-park-calibration` (needs the data; about 25 minutes on one core)
writes victoria_park_calibration.md/.csv and victoria_park_ute.toml; the preset
experiments/presets/victoria_park_ute.toml is that file. The procedure never looks at the GPS error
of a SLAM run: it maximises the likelihood of the filter's own innovations (the prediction-error
method of system identification), on the first 2000 scans (the part with raw laser data), so
scans 2001-7249 stay untouched by it.

First the steering calibration (`slam.SteeringCalibration`: alpha = offset + gain r +
cubic r^3 from the reading r), fitted by dead reckoning against the GPS stretches of the same
scans (experiments/paper/victoria_park/steering.py; no filter involved), then held fixed.

Fixed before the fit (not fitted):
- the filter: first-estimates Jacobians (FEJ), which keep the global heading unobservable as it
  is (without them the filter grows overconfident in its heading and the map turns by 4-6
  degrees over the first kilometre);
- the start: during the fit, the dead-reckoning fit to the GPS of the first 50 m (`slam.start`;
  the likelihood of the innovations does not depend on where the map's frame is), with a
  1 degree floor on the heading sigma and 0.3 m on the position. The preset's start is derived
  last, with the fitted noise (`vp_start`): the filter's own path fitted to the GPS over the
  first D metres, D the shortest stretch from which longer ones agree on the heading;
- the published detections (`det_method` "bailey") with the constant noise model
  sigma_range = a + b r, sigma_bearing = c (t = 0: the detections' bearing error does not grow
  at short range), IHGR association, the default gates and map policy. The preset gives the
  same model to every extractor (measurement_noise "constant"): real trunks, not the fits'
  idealised circles, set the error;
- the scans of a ute standing still are not used (`min_travel_m` 1 mm): on scans 1-2000 the
  measurements of a landmark seen again from the same place have innovations correlated 0.35
  (range) and 0.49 (bearing) with the last ones and a NIS of 0.13 per dof: they repeat the last
  scan's errors.

Fitted (Nelder-Mead on the yaw and the sigmas' logarithms, `EVALUATIONS` evaluations from the
Zaragoza SLAM-school model and an odometry noise of 0.5 m/s and 3 degrees, initial steps 0.02 rad
and x1.35): the laser's yaw on the vehicle, the odometry noise (speed, steering) and the
measurement noise (a, b, c), twice: with a constant odometry noise, and with its growth with the
speed and the lateral acceleration as well (`slam.OdometryNoise`), because a constant model's
errors can depend on the motion (before the steering was calibrated, the scans' NIS per dof on
scans 1-2000 rose from 0.77 at lateral accelerations under 0.05 m/s^2 to 1.59 above 0.6 m/s^2).
The second model contains the first (growth 0), so its fit starts from the first fit's optimum
with growth terms of 0.01 per m/s and 0.01 rad per m/s^2 (`GROWTH_START`). The model with the
lower Bayesian information criterion (2 J + parameters x ln(measurements)) goes on
(`select_model`).
The objective is the negative log-likelihood of the run:

    J = sum over scans with an update  1/2 (nu^T S^-1 nu + ln |2 pi S|)
        + (measurements not used in an update) * ln(80 m * pi rad)

the second term charging every measurement the filter leaves unexplained (a new or ambiguous
landmark, clutter) the density of a uniform return over the field of view, as IHGR's costs do;
without it, noise so small that most measurements fail the gate would look likely.

Then a consistency step (`consistency_scale`): that charge also rewards noise wide enough to
explain the real errors' heavy tail, and the fitted filter is conservative on the ordinary scan
(NIS per dof 0.78 and 0.88 for the two fits on scans 1-2000). The measurement sigmas
(a, b, c, every extractor) are multiplied by the one factor k that makes the run's NIS per
degree of freedom 1 over the same scans (E[NIS] = dof, the mean of a consistent filter's NIS),
found by bisection on ln k; the odometry noise and the yaw stay as fitted. Again no GPS error
enters, and scans 2001-7249 never do.

Then the laser's latency (`latency_profile`, `derive_latency`): the scans may be stamped when
they arrive, not when they were measured, and the calibration above assumes one clock. With
the fitted noise (after the consistency step), J is evaluated with each scan placed at the pose
`vehicle.laser_latency_s` before its stamp, over the grid `LATENCIES_S`; the latency is the
vertex of the parabola fitted to the whole profile by least squares, kept inside the grid.
The probe of 2026-11-26 (lab notebook) found J about 340 lower at 60 ms
than at 0. No GPS error enters it; the noise is not refitted at the new latency.

Then, with the fitted noise, latency and start, the map policy's `confirm_scans` (every fit
above uses the paper's 3): the number with the best map against the 2002 SLAM school's
reference trees of the same scans (`vp_map_policy.confirm_sweep`, `derive_confirm`; no GPS
either).

Then, with every setting above, the published detections' range error (`derive_range_bias`,
`experiments.eval.trace_bias`): a static trunk's sightings within a pass, projected through the
filter's poses, trace a shape that a range offset and scale draw along the line of sight; the
range bias (a, b) of `measurement.range_bias.bailey` (r -> r - (a + b r); the detections'
method, which our `bailey` extractor on the raw scans shares) is the fixed point of running
the filter with it and fitting what is left, on the same scans. J cannot see it either: the
filter's poses and map take the error up, and its innovations are then small. No GPS.

Last, with every setting above (the preset, white measurement errors), the trunk's centre
offset shared by a pass (`measurement.pass_offset_sd_m`) by leave-one-pass-out prediction of
the landmarks' passes on the same scans (`pass_offset.derive`,
`experiments.eval.pass_offsets`): J cannot see it, it assumes white errors; and from the same
run, how that offset drifts within a pass as the view turns (`experiments.eval.pass_drift`,
the correlation length of `measurement.pass_offset_corr_rad`, reported in the manifest as
`pass_offset_corr_rad`). No GPS either.
It is derived and reported (manifest, page), not put in the preset: the filter model it
feeds, each sighting's covariance inflated so that a pass carries at most 1 / (r/n + s^2),
is not a consistent model of a view-dependent offset (simulated oval trunks: the trunk-shape
page and the lab notebook), and the preset keeps white errors until one is.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from experiments.errors import ConfigError, MissingDataError
from experiments.eval import trace_bias
from experiments.io.config_file import preset_toml
from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
from experiments.io.writers import write_atomic
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.victoria_park import map_policy as vp_map_policy
from experiments.paper.victoria_park import pass_offset as vp_pass_offset
from experiments.paper.victoria_park import start as vp_start
from experiments.paper.victoria_park import steering as vp_steering
from experiments.paper.victoria_park.steering import fit_steering
from slam import OdometryNoise, SlamConfig, SteeringCalibration, run_slam
from slam.log import SKIPPED
from slam.measurement import NoiseModel

__all__ = [
    "BASE",
    "FIT_SCANS",
    "TABLES",
    "VpCalibration",
    "calibrate",
    "calibration_records",
    "calibration_study",
    "config_from",
    "consistency_scale",
    "derive_latency",
    "latency_profile",
    "nis_per_dof",
    "objective",
    "preset_config",
    "run",
    "scale_measurement_noise",
]

log = logging.getLogger(__name__)

FIT_SCANS = 2000
RANGE_BIAS_METHOD = "bailey"  # the published detections' det_method: the key of their range bias
RANGE_BIAS_RUNS = 6  # the fixed point's bound (Victoria Park: 3 runs)
MAX_WIDENINGS = 4  # of the consistency step's bracket (x16 either way)
EVALUATIONS = {False: 200, True: 320}  # Nelder-Mead's budget, without and with the motion terms
LN_AREA = math.log(80.0 * math.pi)  # the measurement space of the ute's laser, m x rad
# the laser latencies J is profiled over (s): the probe's -0.15..+0.1 s shift found the lowest
# J near 60 ms (lab notebook, 2026-11-26); a grid around it, the fitted parabola refines it
LATENCIES_S = (-0.04, -0.02, 0.0, 0.02, 0.04, 0.06, 0.08, 0.10, 0.12)
QUICK_LATENCIES_S = (0.0, 0.06, 0.12)
BASE = SlamConfig().with_(
    **{
        "features.method": "detections",
        "filter.first_estimates_jacobians": True,
        "start.gps_fit_m": 50.0,
        "start.gps_sigma_m": 0.3,
        "start.heading_sigma_rad": math.radians(1.0),
        # the simulated extractors' fit floors and range biases belong to the simulated LMS200
        # and tree park; on the real ute they are unknown: none (as in the preset)
        "measurement.fit_floor_range_m": 0.0,
        "measurement.fit_floor_bearing_rad": 0.0,
        "measurement.range_bias": {
            "paper": [0.0, 0.0],
            "geometric": [0.0, 0.0],
            "bailey": [0.0, 0.0],
        },
        # the scans of a ute standing still repeat the last one's errors: not used
        "vehicle.min_travel_m": 0.001,
        # the ute (wheelbase 2.83 m, encoder 0.76 m off the axle centre): what the fit describes
        "vehicle.calibrated_for": [2.83, 0.76],
    }
)
# laser yaw (rad), ln speed sigma (m/s), ln steer sigma (rad), ln a (m), ln b (-), ln c (rad),
# ln speed sigma per speed (-), ln steer sigma per lateral acceleration (rad per m/s^2)
START = np.array(
    [0.0, *np.log([0.5, math.radians(3.0), 0.05, 0.01, math.radians(0.5), 0.05, 0.05])]
)
STEPS = np.array([0.02, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3])
GROWTH_START = np.log([0.01, 0.01])  # the motion terms where the nested fit starts them
MEASUREMENT = [3, 4, 5]  # the measurement sigmas' entries of theta
NAMES = (
    "laser_yaw_rad",
    "speed_sigma_mps",
    "steer_sigma_rad",
    "range_sigma_m",
    "range_sigma_per_m",
    "bearing_sigma_rad",
    "speed_sigma_per_speed",
    "steer_sigma_per_lateral_mps2",
)


def config_from(theta, base: SlamConfig = BASE, laser=(3.78, 0.50)) -> SlamConfig:
    """The configuration of parameter vector theta (see START for its layout): its first 6
    entries (a constant odometry noise) or all 8 (with the motion-dependent terms, the
    preset's model)."""
    if len(theta) not in (6, 8):
        raise ConfigError(f"theta: expected 6 or 8 parameters, got {len(theta)}")
    yaw, lsv, lsa, la, lb, lc = (float(v) for v in theta[:6])
    model = NoiseModel(math.exp(la), math.exp(lb), math.exp(lc), 0.0)
    growth = [math.exp(float(v)) for v in theta[6:]] or [0.0, 0.0]
    odometry = OdometryNoise(
        math.exp(lsv),
        math.exp(lsa),
        speed_sigma_per_speed=growth[0],
        steer_sigma_per_lateral_mps2=growth[1],
    )
    return base.with_(
        **{
            "vehicle.odometry_noise": odometry,
            "vehicle.laser_pose": [laser[0], laser[1], yaw],
            "measurement.noise": "constant",
            "measurement.constant_noise": {
                m: model._asdict() for m in ("bailey", "paper", "geometric", "other")
            },
        }
    )


def objective(seq, theta, base: SlamConfig = BASE) -> tuple[float, dict]:
    """J(theta) on `seq` and the run's figures (landmarks, NIS per dof, unexplained count);
    `base`: the fixed settings (BASE with the fitted steering calibration)."""
    cfg = config_from(theta, base)
    lg = run_slam(seq, cfg)
    upd = lg.scan_nis_dof > 0
    nll = 0.5 * float(
        np.sum(
            lg.scan_nis[upd] + lg.scan_logdet[upd] + lg.scan_nis_dof[upd] * math.log(2 * math.pi)
        )
    )
    counted = lg.meas_status != SKIPPED  # the measurements J accounts for
    unexplained = int(np.sum(counted & (lg.meas_status < 0)))
    info = {
        "landmarks": int(lg.landmark_xy.shape[0]),
        "nis_per_dof": float(np.sum(lg.scan_nis[upd]) / max(lg.scan_nis_dof[upd].sum(), 1)),
        "unexplained": unexplained,
        "measurements": int(counted.sum()),
    }
    return nll + unexplained * LN_AREA, info


def calibrate(
    seq,
    max_evaluations: int = 150,
    progress=None,
    motion_terms: bool = False,
    base: SlamConfig = BASE,
    start=None,
) -> dict:
    """Minimise J over theta from `start` (default START); returns the fitted values, J and
    the run's figures. motion_terms: also fit the odometry noise's growth with speed and
    lateral acceleration (8 parameters)."""
    n = 8 if motion_terms else 6
    start = START[:n] if start is None else np.asarray(start, dtype=float)
    if start.shape != (n,):
        raise ConfigError(f"start: expected {n} parameters, got {start.shape}")
    steps = STEPS[:n]
    evals = []

    def f(theta):
        J, info = objective(seq, theta, base)
        evals.append((J, info))
        if progress is not None:
            progress("Victoria Park calibration", len(evals), max_evaluations)
        return J

    # the initial simplex: +0.02 rad of yaw (about 1 deg) and x1.35 on each sigma; scipy's
    # default (+0.00025 for a parameter at 0) would leave the yaw where it starts
    simplex = np.vstack([start, start + np.diag(steps)])
    res = minimize(
        f,
        start,
        method="Nelder-Mead",
        options={
            "maxfev": max_evaluations,
            "xatol": 1e-3,
            "fatol": 1.0,
            "initial_simplex": simplex,
        },
    )
    J, info = objective(seq, res.x, base)
    theta = res.x
    values = dict(zip(NAMES[:n], [theta[0], *np.exp(theta[1:])]))
    return {"values": values, "theta": theta.tolist(), "J": J, "evaluations": len(evals), **info}


def scale_measurement_noise(cfg: SlamConfig, k: float) -> SlamConfig:
    """`cfg` with the sigmas (range a and b, bearing c, cross-range) of every constant
    measurement-noise model multiplied by k > 0."""
    if not (math.isfinite(k) and k > 0):
        raise ConfigError(f"k: the noise factor must be a positive number, got {k!r}")
    scaled = {
        name: NoiseModel(
            m.range_sigma_m * k,
            m.range_sigma_per_m * k,
            m.bearing_sigma_rad * k,
            m.cross_range_sigma_m * k,
        )
        for name, m in cfg.measurement.constant_noise.items()
    }
    return cfg.with_(**{"measurement.constant_noise": {n: m._asdict() for n, m in scaled.items()}})


def nis_per_dof(seq, cfg: SlamConfig) -> float:
    """Sum of the scans' NIS over the sum of their degrees of freedom, for a run over `seq`
    with the published detections and IHGR (NaN without an update)."""
    lg = run_slam(seq, cfg)
    upd = lg.scan_nis_dof > 0
    dof = int(lg.scan_nis_dof[upd].sum())
    return float(np.sum(lg.scan_nis[upd]) / dof) if dof else math.nan


def consistency_scale(
    seq, cfg: SlamConfig, bracket=(0.5, 2.0), iterations: int = 7, progress=None
) -> dict:
    """The factor k on the measurement sigmas (`scale_measurement_noise`) that makes the run's
    NIS per dof 1, by bisection on ln k (NIS falls as k grows).

    The search starts from `bracket` and widens it (each end x2 outward, at most
    `MAX_WIDENINGS` times) until NIS per dof is >= 1 at its low end and <= 1 at its high end;
    then `iterations` bisection steps. Returns {"k" (the evaluated factor closest to NIS per
    dof 1), "nis_per_dof" (at k), "evaluations": [(k, nis_per_dof), ...]}. Raises ConfigError
    for a bad bracket or when no widened bracket contains the crossing."""
    evals: list[tuple[float, float]] = []

    def f(k: float) -> float:
        v = nis_per_dof(seq, scale_measurement_noise(cfg, k))
        evals.append((k, v))
        if progress is not None:
            progress("Victoria Park consistency", len(evals), iterations + 2)
        return v

    lo, hi = (float(b) for b in bracket)
    if not (0 < lo < hi and math.isfinite(hi)):
        raise ConfigError(f"bracket: expected 0 < low < high, got {bracket!r}")
    f_lo, f_hi = f(lo), f(hi)
    for _ in range(MAX_WIDENINGS):
        if f_lo < 1.0:  # noise still too wide at the low end: go lower
            lo, hi, f_hi = lo / 2.0, lo, f_lo
            f_lo = f(lo)
        elif f_hi > 1.0:
            lo, hi, f_lo = hi, hi * 2.0, f_hi
            f_hi = f(hi)
        else:
            break
    if not (f_lo >= 1.0 >= f_hi):
        raise ConfigError(
            f"bracket: NIS per dof is {f_lo:.3g} at k = {lo:g} and {f_hi:.3g} at k = {hi:g} "
            f"after widening {bracket!r} {MAX_WIDENINGS} times; 1 is not between them"
        )
    for _ in range(iterations):
        mid = math.sqrt(lo * hi)
        if f(mid) >= 1.0:
            lo = mid
        else:
            hi = mid
    best = min(evals, key=lambda e: abs(e[1] - 1.0))
    return {"k": best[0], "nis_per_dof": best[1], "evaluations": evals}


def latency_profile(seq, theta, base: SlamConfig = BASE, latencies=LATENCIES_S, progress=None):
    """[(latency_s, J), ...]: J (`objective`) of the parameters `theta` with each scan placed
    at the pose `latency_s` before its stamp (`vehicle.laser_latency_s`), for each latency."""
    rows = []
    for i, latency in enumerate(latencies):
        cfg = base.with_(**{"vehicle.laser_latency_s": float(latency)})
        rows.append((float(latency), objective(seq, theta, cfg)[0]))
        if progress is not None:
            progress("Victoria Park laser latency", i + 1, len(latencies))
    return rows


def derive_latency(rows) -> float:
    """The latency of `latency_profile`'s rows: the vertex of the parabola fitted to the whole
    profile by least squares, kept inside the grid; the lowest J's latency when the fit does
    not curve upwards. The whole profile, not the lowest J and its neighbours: on scans
    1-2000 J moves by tens at the 20 ms scale as associations flip (at 712572a J was within
    65 of its lowest from 20 to 80 ms), and a three-point parabola follows those bumps."""
    if len(rows) < 1:
        raise ConfigError("latency profile: no rows")
    lat = np.array([r[0] for r in rows], dtype=float)
    J = np.array([r[1] for r in rows], dtype=float)
    if np.any(np.diff(lat) <= 0) or not np.all(np.isfinite(J)):
        raise ConfigError("latency profile: latencies must increase and every J be finite")
    lowest = float(lat[int(np.argmin(J))])
    if lat.size < 3:
        return lowest
    a, b, _ = np.polyfit(lat, J, 2)
    if a <= 0:
        return lowest
    vertex = -b / (2 * a)
    if not lat[0] < vertex < lat[-1]:
        log.warning("the fitted latency %.3f s is outside the grid: widen LATENCIES_S", vertex)
    return float(np.clip(vertex, lat[0], lat[-1]))


@dataclass(frozen=True)
class VpCalibration:
    """The results of the calibration, in the order found.

    steer: the steering fit (`vp_steering.fit_steering`); fits: motion terms (False, True) ->
    `calibrate`'s result; motion: the lower BIC's (`select_model`); start: (J, the run's
    figures) at START; consistency: `consistency_scale`'s result; theta: the preset's
    parameters (the chosen fit, measurement sigmas x k) and final: (J, figures) there;
    latency_rows: `latency_profile` at the preset's noise, latency_s: its `derive_latency`;
    start_rows: `vp_start.headings` along the preset's path; start_fit_m: the metres of GPS the
    start is fitted to (`vp_start.derive`); confirm_rows: `vp_map_policy.confirm_sweep` with
    that noise and start, confirm_scans: its `derive_confirm`; range_bias: (a m, b per m) of the
    published detections (`derive_range_bias`), range_bias_fits: the trace fit of each of its
    runs; pass_offset: the pass offset derived with all of these (`vp_pass_offset.derive`);
    seconds: the time it took.
    """

    steer: object
    fits: dict
    motion: bool
    start: tuple[float, dict]
    consistency: dict
    theta: np.ndarray
    final: tuple[float, dict]
    latency_rows: list
    latency_s: float
    start_rows: list
    start_fit_m: float
    confirm_rows: list
    confirm_scans: int
    range_bias: tuple[float, float]
    range_bias_fits: list
    pass_offset: object
    seconds: float

    def preset(self) -> SlamConfig:
        """The preset's configuration (`preset_config`)."""
        return preset_config(
            self.theta,
            self.steer.steering,
            self.start_fit_m,
            self.confirm_scans,
            latency_s=self.latency_s,
            range_bias=self.range_bias,
        )  # the pass offset is derived, not adopted (module doc)


def calibration_study(seq, full, ref, quick: bool = False, progress=None) -> VpCalibration:
    """The whole procedure (the module doc) on `seq` (scans 1-`FIT_SCANS`), the steering fit's
    held-out GPS stretches from `full`, the map policy judged against `ref` (ground, trees;
    `load_ss2002_reference`). quick: a few evaluations of each step (a smoke run)."""
    t0 = time.perf_counter()
    steer = fit_steering(full, FIT_SCANS, 10 if quick else vp_steering.EVALUATIONS)
    base = BASE.with_(**{"vehicle.steering": steer.steering})
    fits = {}
    for motion in (False, True):
        n = 5 if quick else EVALUATIONS[motion]
        # the motion-dependent model contains the constant one (growth 0): its fit starts from
        # the constant fit's optimum with small growth terms, so it can only do better
        start = np.r_[fits[False]["theta"], GROWTH_START] if motion else None
        fits[motion] = calibrate(seq, n, progress, motion_terms=motion, base=base, start=start)
    motion = select_model(fits[False], fits[True])
    fit = fits[motion]
    at_start = objective(seq, START[:6], base)
    cons = consistency_scale(seq, config_from(fit["theta"], base), iterations=1 if quick else 7)
    theta = np.asarray(fit["theta"], dtype=float)
    theta[MEASUREMENT] += math.log(cons["k"])
    grid = QUICK_LATENCIES_S if quick else LATENCIES_S
    latency_rows = latency_profile(seq, theta, base, grid, progress)
    latency = derive_latency(latency_rows)
    base = base.with_(**{"vehicle.laser_latency_s": latency})
    final = objective(seq, theta, base)
    start_rows = vp_start.headings(seq, config_from(theta, base))
    start_fit_m = vp_start.derive(start_rows)
    confirm_rows = vp_map_policy.confirm_sweep(
        seq, preset_config(theta, steer.steering, start_fit_m, latency_s=latency), ref
    )
    confirm = vp_map_policy.derive_confirm(confirm_rows)
    at_confirm = preset_config(theta, steer.steering, start_fit_m, confirm, latency_s=latency)
    bias, bias_fits = derive_range_bias(seq, at_confirm, 1 if quick else RANGE_BIAS_RUNS)
    white = preset_config(
        theta, steer.steering, start_fit_m, confirm, latency_s=latency, range_bias=bias
    )
    return VpCalibration(
        steer=steer,
        fits=fits,
        motion=motion,
        start=at_start,
        consistency=cons,
        theta=theta,
        final=final,
        latency_rows=latency_rows,
        latency_s=latency,
        start_rows=start_rows,
        start_fit_m=start_fit_m,
        confirm_rows=confirm_rows,
        confirm_scans=confirm,
        range_bias=bias,
        range_bias_fits=bias_fits,
        pass_offset=vp_pass_offset.derive(seq, white),
        seconds=time.perf_counter() - t0,
    )


def _manifest_entry(st: VpCalibration) -> dict:
    """What the manifest records of the calibration."""
    s = st.steer
    fits = st.fits
    return {
        "scans": FIT_SCANS,
        "steering": {
            "offset_rad": s.steering.offset_rad,
            "gain": s.steering.gain,
            "cubic_per_rad2": s.steering.cubic_per_rad2,
            "stretches": [s.fit_stretches, s.held_out_stretches],
            "fit_mse_m2": [s.fit_mse_before, s.fit_mse_after],
            "held_out_mse_m2": [s.held_out_mse_before, s.held_out_mse_after],
        },
        "evaluations": {
            "constant": fits[False]["evaluations"],
            "motion": fits[True]["evaluations"],
        },
        "start": dict(zip(NAMES, [START[0], *np.exp(START[1:])])),
        "fitted_constant": fits[False]["values"],
        "fitted_motion": fits[True]["values"],
        "bic": {"constant": bic(fits[False]), "motion": bic(fits[True])},
        "chosen": "motion" if st.motion else "constant",
        "consistency_factor": st.consistency["k"],
        "laser_latency_s": st.latency_s,
        "latency_profile": st.latency_rows,
        "start_fit_m": st.start_fit_m,
        "start_headings_deg": st.start_rows,
        "confirm_scans": st.confirm_scans,
        "confirm_sweep": st.confirm_rows,
        "range_bias": {RANGE_BIAS_METHOD: list(st.range_bias)},
        "range_bias_runs": [
            {"bias": list(b), **dataclasses.asdict(f)} for b, f in st.range_bias_fits
        ],
        "pass_offset_sd_m": list(st.pass_offset.sd_m),
        "pass_offset_median_white": list(st.pass_offset.median_white),
        "pass_offset_corr_rad": st.pass_offset.drift.corr_rad,
        "pass_offset_drift_sd_m": list(st.pass_offset.drift.sd_m),
        "consistency_evaluations": st.consistency["evaluations"],
        "seconds": round(st.seconds, 1),
    }


def calibration_records(st: VpCalibration) -> list[dict]:
    """The calibration table's records: the start, each fit, the preset (one row each)."""
    fits = st.fits
    rows = (
        ("start (SLAM-school model, 0.5 m/s, 3 deg)", START[:6], *st.start),
        (
            f"maximum likelihood, constant odometry noise (BIC {bic(fits[False]):.0f})",
            fits[False]["theta"],
            fits[False]["J"],
            fits[False],
        ),
        (
            f"maximum likelihood, motion-dependent odometry noise (BIC {bic(fits[True]):.0f})",
            fits[True]["theta"],
            fits[True]["J"],
            fits[True],
        ),
        (
            "preset: the lower BIC, measurement sigmas x "
            f"{st.consistency['k']:.3f} (NIS per dof 1)",
            st.theta,
            *st.final,
        ),
    )
    return [
        {
            "parameters": name,
            **dict(zip(CALIBRATION_LABELS, _row(theta))),
            "j": J,
            "landmarks": info["landmarks"],
            "nis_per_dof": info["nis_per_dof"],
            "unexplained_measurements": info["unexplained"],
        }
        for name, theta, J, info in rows
    ]


def _calibration_notes(st: VpCalibration) -> str:
    steer, fits = st.steer, st.fits
    return (
        f"{fits[False]['evaluations']} and {fits[True]['evaluations']} evaluations of the run "
        f"over scans 1-{FIT_SCANS} with the published detections (IHGR, FEJ, GPS start fit "
        "over 50 m, scans at rest skipped). J: the negative log-likelihood of the "
        "innovations plus ln(80 m pi rad) per unexplained measurement "
        "(experiments/paper/victoria_park/calibration.py); BIC = 2 J + parameters x "
        "ln(measurements). "
        "Last row: the preset, the fit with the lower BIC, its measurement sigmas scaled by "
        "the factor that makes the NIS per dof 1 on the same scans (bisection). No GPS error "
        "enters it. Steering calibration, fixed in every row (experiments/paper/"
        f"vp_steering.py, dead reckoning against {steer.fit_stretches} GPS stretches of "
        f"{vp_steering.STRETCH_S:.0f} s of the same scans): offset "
        f"{math.degrees(steer.steering.offset_rad):.3f} deg, gain {steer.steering.gain:.4f}, "
        f"cubic {steer.steering.cubic_per_rad2:.4f} per rad^2; the stretches' mean squared "
        f"distance {steer.fit_mse_before:.2f} -> {steer.fit_mse_after:.2f} m^2 (the "
        f"{steer.held_out_stretches} stretches of scans 2001-7249, never fitted: "
        f"{steer.held_out_mse_before:.2f} -> {steer.held_out_mse_after:.2f} m^2)."
    )


def _start_notes(st: VpCalibration) -> str:
    return (
        "The filter's path over scans 1-2000 (the preset's noise, published detections, "
        "IHGR) fitted rigidly to the GPS fixes of its first D metres (slam.start."
        f"fit_gps_start_to_track); last row: the whole path. Chosen: D = {st.start_fit_m:.0f} m, "
        f"the shortest D from which every longer fit is within {vp_start.TOLERANCE_DEG} deg "
        "of the whole path's (experiments/paper/victoria_park/start.py). No GPS error of a run "
        "enters "
        "it."
    )


@experiment(
    "victoria-park-calibration",
    order=100,
    page="victoria-park.md",
    help="the ute's noise and laser yaw (only when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `victoria-park-calibration`."""
    try:
        seq = load_victoria_park(n_scans=FIT_SCANS)
        full = load_victoria_park(full=True)  # the steering fit's held-out GPS stretches
        ref = load_ss2002_reference()  # the map policy's judge
    except MissingDataError as exc:
        log.warning("Victoria Park calibration skipped: %s", exc)
        ctx.config["victoria-park-calibration"] = f"skipped: {exc}"
        return
    st = calibration_study(seq, full, ref, quick=ctx.quick, progress=ctx.progress)
    ctx.config["victoria-park-calibration"] = _manifest_entry(st)
    products.tables(ctx, TABLES, st)
    ctx.outputs.append(
        write_atomic(ctx.path("victoria_park_ute.toml"), preset_toml(st.preset(), PRESET_HEADER))
    )


def derive_range_bias(seq, cfg: SlamConfig, max_runs: int) -> tuple[tuple[float, float], list]:
    """The published detections' range bias on `seq` with `cfg`'s other settings
    (`trace_bias.derive_range_bias`, its fixed point within `max_runs` runs; the module doc):
    ((a m, b per m), one (bias, `TraceFit`) per run). A smoke run (`max_runs` 1) that has not
    settled returns its one fit's composition."""

    def run(bias):
        return run_slam(seq, cfg.with_(**{"measurement.range_bias": {RANGE_BIAS_METHOD: bias}}))

    if max_runs > 1:
        return trace_bias.derive_range_bias(run, max_iterations=max_runs)
    fit = trace_bias.trace_fit(run((0.0, 0.0)))
    return trace_bias.compose_range_bias((0.0, 0.0), fit), [((0.0, 0.0), fit)]


def preset_config(
    theta,
    steering: SteeringCalibration,
    start_fit_m: float,
    confirm_scans: int | None = None,
    latency_s: float = 0.0,
    pass_offset_sd_m=(0.0, 0.0),
    range_bias=(0.0, 0.0),
) -> SlamConfig:
    """The preset: the fixed settings (BASE), the fitted parameters `theta` (the model's 6 or
    8), the steering calibration, the start fitted along the filter's own path over the
    first `start_fit_m` metres of GPS (`vp_start`), the map policy's `confirm_scans`
    (`vp_map_policy.derive_confirm`; None: BASE's, the paper's 3), the laser latency
    (`derive_latency`), the published detections' `range_bias` (a m, b per m;
    `derive_range_bias`); white errors unless `pass_offset_sd_m` is given (the calibration
    derives the pass offset, `vp_pass_offset.derive`, and does not set it)."""
    confirm = BASE.map_policy.confirm_scans if confirm_scans is None else int(confirm_scans)
    base = BASE.with_(
        **{
            "vehicle.steering": steering,
            "start.gps_track": "slam",
            "start.gps_fit_m": float(start_fit_m),
            "map_policy.confirm_scans": confirm,
            "vehicle.laser_latency_s": float(latency_s),
            "measurement.pass_offset_sd_m": [float(v) for v in pass_offset_sd_m],
            "measurement.range_bias": dict(BASE.measurement.range_bias)
            | {RANGE_BIAS_METHOD: tuple(map(float, range_bias))},
        }
    )
    return config_from(theta, base)


PRESET_HEADER = """\
The Victoria Park ute: `trunkslam reproduce victoria-park-calibration`
(experiments/paper/victoria_park/calibration.py) fitted the steering calibration by dead
reckoning against GPS stretches of scans 1-2000, then the laser yaw, odometry noise and
measurement noise by maximum likelihood of the filter's own innovations on the same scans (no
GPS error of a SLAM run is used), then scaled the measurement sigmas by the factor that makes
the NIS per dof 1 there,
then the laser latency from a profile of the same likelihood, then chose the metres of GPS the
start is fitted to along the filter's own path (the shortest stretch from which longer ones
agree on the heading). Fixed: FEJ, start floors 0.3 m and 1 deg,
the same constant measurement model for every extractor, scans at rest skipped (1 mm).
Then the map policy's confirm_scans: the best map (F1) against the 2002 reference trees.
Then the published detections' range bias (measurement.range_bias.bailey, which our bailey
extractor shares): the fixed point of the trunks' traces within a pass on scans 1-2000
(experiments/eval/trace_bias.py).
Last, the trunk's offset shared by a pass: derived by the leave-one-pass-out criterion on
scans 1-2000 (experiments/eval/pass_offsets.py) and reported in the manifest, not set here:
white errors (measurement.pass_offset_sd_m = [0, 0]; its page says why).
Its extractor parameters are the defaults, short trunks included: most real trunks span 1-3 beams.
Use: trunkslam slam vp_full.npz --config victoria_park_ute"""

START_LABELS = {
    "fit_m": "GPS stretch D (m of path)",
    "start_heading_deg": "start heading (deg)",
    "fixes": "fixes",
}

CALIBRATION_LABELS = {  # the fitted parameters' fields (in `_row`'s order) and the table's headers
    "laser_yaw_deg": "laser yaw (deg)",
    "speed_sigma_m_s": "speed sigma (m/s)",
    "steer_sigma_deg": "steer sigma (deg)",
    "range_sigma_a_m": "range sigma a (m)",
    "range_sigma_b_per_m": "range sigma b (per m)",
    "bearing_sigma_c_deg": "bearing sigma c (deg)",
    "speed_sigma_per_speed": "speed sigma per m/s of speed",
    "steer_sigma_deg_per_lateral_mps2": "steer sigma per m/s^2 of lateral acceleration (deg)",
    "j": "J",
    "nis_per_dof": "NIS per dof",
    "unexplained_measurements": "unexplained measurements",
}


TABLES = (
    TableSpec(
        "victoria_park_calibration",
        calibration_records,
        index=("parameters",),
        values=None,
        labels=CALIBRATION_LABELS,
        title="Victoria Park: the ute's noise and laser yaw by maximum likelihood (scans 1-2000)",
        notes=_calibration_notes,
    ),
    TableSpec(
        "victoria_park_latency",
        lambda st: [{"latency_ms": 1e3 * lat, "j": J} for lat, J in st.latency_rows],
        index=("latency_ms",),
        values=("j",),
        labels={"latency_ms": "laser latency (ms)", "j": "J"},
        title="Victoria Park: the calibration's J against the laser latency (scans 1-2000)",
        notes=lambda st: (
            "J (experiments/paper/victoria_park/calibration.py) with the preset's noise, each "
            "scan placed "
            "at the pose this long before its stamp (vehicle.laser_latency_s). Chosen: "
            f"{1e3 * st.latency_s:.1f} ms, the vertex of the parabola fitted to the whole "
            "profile (least squares). No GPS error of a run enters it."
        ),
    ),
    dataclasses.replace(  # its own name: victoria-park-pass-offset writes the shipped preset's
        vp_pass_offset.TABLE,
        stem="victoria_park_calibration_pass_offset",
        records=lambda st: vp_pass_offset.pass_offset_records(st.pass_offset),
    ),
    TableSpec(
        "victoria_park_start",
        lambda st: [{"fit_m": d, "start_heading_deg": h, "fixes": n} for d, h, n in st.start_rows],
        index=("fit_m",),
        values=("start_heading_deg", "fixes"),
        labels=START_LABELS,
        title="Victoria Park: the start heading against the metres of GPS it is fitted to",
        notes=_start_notes,
    ),
)


def bic(fit: dict) -> float:
    """Bayesian information criterion of a `calibrate` result: 2 J + p ln(measurements)."""
    return 2.0 * fit["J"] + len(fit["theta"]) * math.log(fit["measurements"])


def select_model(constant: dict, motion: dict) -> bool:
    """True when the fit with the motion-dependent odometry noise has the lower BIC (its two
    extra parameters must buy more likelihood than they cost)."""
    return bic(motion) < bic(constant)


def _row(theta) -> list:
    yaw, lsv, lsa, la, lb, lc = theta[:6]
    lsv1, lsa1 = theta[6:] if len(theta) == 8 else (-math.inf, -math.inf)
    return [
        math.degrees(yaw),
        math.exp(lsv),
        math.degrees(math.exp(lsa)),
        math.exp(la),
        math.exp(lb),
        math.degrees(math.exp(lc)),
        math.exp(lsv1),
        math.degrees(math.exp(lsa1)),
    ]

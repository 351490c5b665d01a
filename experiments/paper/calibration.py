"""Calibration of the `cycab` preset's measurement model (experiments/presets/cycab.toml).

`trunkslam reproduce noise-calibration` simulates four
Cycab runs in the tree park on seeds 1000-1003, apart from experiment 2's, each on a path varied
as in experiment 2 (`experiments.sim.trajectory.MONTE_CARLO_PATH`: runs along one path would be
four copies of one geometry, and the extractors' errors are fixed by it), extracts circles with
each method, and fits sigma_range = a + b r and sigma_bearing^2 = c^2 + (t / r)^2 to the centre
errors of the circles found on trunks by maximum likelihood. Writes noise_calibration.md/.csv.
The `cycab` preset's constant noise models are these fits rounded up to two digits.
It also fits each extractor's mean range error a + b r by maximum likelihood under the sigmas
the filter gives its circles (`range_bias_line`; the preset's `measurement.range_bias`), and
the floors of the geometric fit's covariance (`calibrate_fit_floor`, noise_calibration_floor).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from experiments.eval.detections import dominant_label, run_labels
from experiments.exec import SerialExecutor
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.slam import CYCAB_SLAM, METHODS, extractor_params
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import interpolate_poses, se2, wrap_angle
from slam.measurement import measurements_from_features

__all__ = [
    "FLOOR_QUANTITIES",
    "NOISE_QUANTITIES",
    "SEEDS",
    "TABLES",
    "Calibration",
    "Quantity",
    "calibrate_fit_floor",
    "calibrate_measurement_noise",
    "calibration_trial",
    "quantity_records",
    "range_bias_line",
    "run",
]

SEEDS = (1000, 1001, 1002, 1003)


def calibration_trial(job: tuple, seed) -> dict:
    """One simulated run (`job` = (cycab, scene)) of the calibration: method -> list of (true
    range, range error, bearing error, range variance the filter gives the circle) of the
    circles found on trunks. The variance is the simulated Cycab's configuration's (`CYCAB_SLAM`:
    the constant model in use, or the fit's covariance with its floors), before any range
    bias."""
    cycab, scene = job
    errs: dict[str, list] = {m: [] for m in METHODS}
    seq = simulate_cycab_run(np.random.default_rng(seed), scene, cycab)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    lm = seq.truth_landmarks
    cfg = CYCAB_SLAM.measurement
    for k in range(seq.n_scans):
        lw = se2.compose(truth[k], seq.laser_pose)
        d = lm[:, :2] - lw[:2]
        tr = np.hypot(*d.T)
        tb = np.arctan2(d[:, 1], d[:, 0]) - lw[2]
        for m in METHODS:
            f = extract_features(seq.scan(k), m, **extractor_params(m, cycab))
            if not f.n_circles:
                continue
            # the filter's noise model, before any range bias (the ranges are the fit's)
            _, R = replace(cfg.model_for(m), range_bias=(0.0, 0.0)).from_features(f)
            for i, ((a, b), p) in enumerate(zip(f.circle_beams, f.circle_params)):
                lab = run_labels(seq.scan_labels[k], a, b)
                j, _, n_ret = dominant_label(lab, returns_only=True)
                if n_ret == 0 or j >= lm.shape[0]:
                    continue
                r = math.hypot(p[0], p[1])
                eb = float(wrap_angle(math.atan2(p[1], p[0]) - tb[j]))
                errs[m].append((tr[j], r - tr[j], eb, float(R[i, 0, 0])))
    return errs


def range_bias_line(r: np.ndarray, err: np.ndarray, var: np.ndarray) -> tuple[float, float]:
    """(a, b) of the mean range error a + b r by maximum likelihood under the filter's own
    noise: Gaussian errors with the variances `var` the filter gives each circle, so weighted
    least squares with weights 1 / var. The circles the filter trusts most weigh most: a
    millimetre of bias in a precise fit matters to the filter as much as centimetres in a
    rough one, which an unweighted line does not see."""
    X = np.column_stack([np.ones_like(r), r])
    w = 1.0 / np.asarray(var, dtype=np.float64)
    a, b = np.linalg.solve(X.T @ (X * w[:, None]), X.T @ (np.asarray(err) * w))
    return float(a), float(b)


def calibrate_measurement_noise(
    seeds=SEEDS, cycab: CycabParams | None = None, scene: str = "tree_park", executor=None
) -> dict:
    """Fit the constant noise model (`slam.measurement.NoiseModel`) to the extractors' centre
    errors on circles found on trunks (majority of beams on one trunk), by maximum likelihood of
    zero-mean Gaussian errors: range error ~ N(0, (a + b r)^2), bearing error ~ N(0, c^2 +
    (t / r)^2) (a bias is absorbed into the spread). Returns method -> dict of the fitted
    values, the RMS errors and the normalised error variances under the fit (1 = calibrated).
    Each seed's run is a trial (`calibration_trial`) on `executor`."""
    import numpy as np

    cycab = cycab or CycabParams(**MONTE_CARLO_PATH)
    got = (executor or SerialExecutor()).map(
        calibration_trial,
        [(cycab, scene)] * len(seeds),
        [np.random.SeedSequence(s) for s in seeds],
        desc="noise calibration runs",
        chunksize=1,
    )
    errs: dict[str, list] = {m: [e for g in got for e in g[m]] for m in METHODS}
    out = {}
    for m, v in errs.items():
        v = np.array(v)
        r, er, eb, var = v[:, 0], v[:, 1], v[:, 2], v[:, 3]

        def nll_range(q, r=r, er=er):
            s = np.abs(q[0]) + np.abs(q[1]) * r
            return float(np.sum(np.log(s) + 0.5 * (er / s) ** 2))

        def nll_bearing(q, r=r, eb=eb):
            s2 = q[0] ** 2 + (q[1] / r) ** 2
            return float(np.sum(0.5 * np.log(s2) + 0.5 * eb**2 / s2))

        qa = _fit(nll_range, [0.01, 0.001], xatol=1e-7)
        qb = _fit(nll_bearing, [0.001, 0.005], xatol=1e-8)
        sr = qa[0] + qa[1] * r
        sb2 = qb[0] ** 2 + (qb[1] / r) ** 2
        bias_ab = range_bias_line(r, er, var)
        out[m] = {
            "n": len(v),
            "range_bias_a_m": bias_ab[0],
            "range_bias_b_per_m": bias_ab[1],
            "range_error_mean_normalised": float(np.mean(er / np.sqrt(var))),
            "range_rms_m": float(np.sqrt(np.mean(er**2))),
            "range_mean_m": float(np.mean(er)),
            "bearing_rms_rad": float(np.sqrt(np.mean(eb**2))),
            "range_sigma_m": float(qa[0]),
            "range_sigma_per_m": float(qa[1]),
            "bearing_sigma_rad": float(qb[0]),
            "cross_range_sigma_m": float(qb[1]),
            "normalised_var_range": float(np.mean((er / sr) ** 2)),
            "normalised_var_bearing": float(np.mean(eb**2 / sb2)),
        }
    return out


def calibrate_fit_floor(
    seeds=SEEDS, cycab: CycabParams | None = None, scene: str = "tree_park", method="geometric"
) -> dict:
    """Maximum-likelihood floors (f_r m, f_b rad) of R = R_fit + diag(f_r^2, f_b^2) for the
    centres of `method`'s circles on trunks (as `calibrate_measurement_noise` finds them), with
    the mean NIS per degree of freedom of the errors under R_fit alone and with the floors."""
    cycab = cycab or CycabParams(**MONTE_CARLO_PATH)
    noise = ("fit", None)
    rows = []
    for seed in seeds:
        seq = simulate_cycab_run(np.random.default_rng(seed), scene, cycab)
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        lm = seq.truth_landmarks
        for k in range(seq.n_scans):
            lw = se2.compose(truth[k], seq.laser_pose)
            f = extract_features(seq.scan(k), method, **extractor_params(method, cycab))
            z, R = measurements_from_features(f, noise)
            for i, (a, b) in enumerate(f.circle_beams):
                j, c, n_ret = dominant_label(run_labels(seq.scan_labels[k], a, b), True)
                if n_ret == 0 or j >= lm.shape[0] or 2 * c <= n_ret:
                    continue
                d = lm[j, :2] - lw[:2]
                er = z[i, 0] - math.hypot(d[0], d[1])
                eb = float(wrap_angle(z[i, 1] - (math.atan2(d[1], d[0]) - lw[2])))
                rows.append((er, eb, R[i, 0, 0], R[i, 0, 1], R[i, 1, 1]))
    A = np.array(rows)

    def nis(q):
        rr, rb, bb = A[:, 2] + q[0] ** 2, A[:, 3], A[:, 4] + q[1] ** 2
        det = rr * bb - rb**2
        v = (bb * A[:, 0] ** 2 - 2 * rb * A[:, 0] * A[:, 1] + rr * A[:, 1] ** 2) / det
        return v, det

    def nll(q):
        v, det = nis(q)
        return float(np.sum(0.5 * np.log(det) + 0.5 * v))

    q = _fit(nll, [0.003, 1e-4], xatol=1e-8)
    return {
        "n": len(A),
        "floor_range_m": float(q[0]),
        "floor_bearing_rad": float(q[1]),
        "nis_per_dof_fit": float(np.mean(nis([0.0, 0.0])[0]) / 2),
        "nis_per_dof_floors": float(np.mean(nis(q)[0]) / 2),
    }


def _fit(nll, start, xatol: float) -> np.ndarray:
    """|argmin| of a negative log-likelihood by Nelder-Mead (the sigmas enter squared or as |q|)."""
    from scipy.optimize import minimize

    opts = {"xatol": xatol, "fatol": 1e-6, "maxiter": 4000}
    return np.abs(minimize(nll, start, method="Nelder-Mead", options=opts).x)


class Quantity(NamedTuple):
    """A column of the calibration tables: where its value comes from ("measured", "fitted",
    "in_use"), what it is, its unit, its header, and how it is read from one method's fit,
    value(method, fit)."""

    source: str
    quantity: str
    unit: str
    label: str
    value: Callable[[str, dict], float]


def _fitted(key: str) -> Callable[[str, dict], float]:
    return lambda method, fit: fit[key]


def _noise_in_use(i: int) -> Callable[[str, dict], float]:
    return lambda method, fit: CYCAB_SLAM.measurement.constant_noise[method][i]


def _bias_in_use(i: int) -> Callable[[str, dict], float]:
    return lambda method, fit: CYCAB_SLAM.measurement.model_for(method).range_bias[i]


# the constant-noise model's fields: (fits key, quantity, unit), in `NoiseModel`'s order
NOISE_FIELDS = (
    ("range_sigma_m", "range_sigma", "m"),
    ("range_sigma_per_m", "range_sigma_per_range", "m/m"),
    ("bearing_sigma_rad", "bearing_sigma", "rad"),
    ("cross_range_sigma_m", "cross_range_sigma", "m"),
)
# noise_calibration's columns, from `calibrate_measurement_noise`'s fits
NOISE_QUANTITIES = (
    Quantity("measured", "circles", "count", "circles", _fitted("n")),
    Quantity("measured", "range_error_mean", "m", "range mean (m)", _fitted("range_mean_m")),
    Quantity(
        "measured",
        "range_error_mean_normalised",
        "1",
        "range mean / filter sigma",
        _fitted("range_error_mean_normalised"),
    ),
    Quantity("measured", "range_error_rms", "m", "range RMS (m)", _fitted("range_rms_m")),
    Quantity(
        "measured", "bearing_error_rms", "rad", "bearing RMS (rad)", _fitted("bearing_rms_rad")
    ),
    *(Quantity("fitted", q, unit, f"fitted {key}", _fitted(key)) for key, q, unit in NOISE_FIELDS),
    *(
        Quantity("in_use", q, unit, f"in use {key}", _noise_in_use(i))
        for i, (key, q, unit) in enumerate(NOISE_FIELDS)
    ),
    *(
        Quantity("fitted", q, "1", q.replace("_", " "), _fitted(q))
        for q in ("normalised_var_range", "normalised_var_bearing")
    ),
    Quantity("fitted", "range_bias_a", "m", "fitted range bias a (m)", _fitted("range_bias_a_m")),
    Quantity(
        "fitted", "range_bias_b", "m/m", "fitted range bias b (m/m)", _fitted("range_bias_b_per_m")
    ),
    Quantity("in_use", "range_bias_a", "m", "in use range bias a (m)", _bias_in_use(0)),
    Quantity("in_use", "range_bias_b", "m/m", "in use range bias b (m/m)", _bias_in_use(1)),
)
_FLOOR = (CYCAB_SLAM.measurement.fit_floor_range_m, CYCAB_SLAM.measurement.fit_floor_bearing_rad)
# noise_calibration_floor's columns, from `calibrate_fit_floor`'s fit
FLOOR_QUANTITIES = (
    Quantity("measured", "circles", "count", "circles", _fitted("n")),
    Quantity("fitted", "floor_range", "m", "floor range (m)", _fitted("floor_range_m")),
    Quantity("fitted", "floor_bearing", "rad", "floor bearing (rad)", _fitted("floor_bearing_rad")),
    Quantity("in_use", "floor_range", "m", "in use range (m)", lambda m, f: _FLOOR[0]),
    Quantity("in_use", "floor_bearing", "rad", "in use bearing (rad)", lambda m, f: _FLOOR[1]),
    Quantity(
        "fitted",
        "nis_per_dof_fit_covariance",
        "1",
        "NIS per dof, fit covariance",
        _fitted("nis_per_dof_fit"),
    ),
    Quantity(
        "fitted",
        "nis_per_dof_with_floors",
        "1",
        "NIS per dof, with floors",
        _fitted("nis_per_dof_floors"),
    ),
)


def quantity_records(fits: dict[str, dict], quantities) -> list[dict]:
    """Tidy records of the fits (method -> fit): per method, one per quantity."""
    return [
        {
            "method": m,
            "source": q.source,
            "quantity": q.quantity,
            "unit": q.unit,
            "value": q.value(m, fit),
        }
        for m, fit in fits.items()
        for q in quantities
    ]


def _table(stem: str, quantities, fits_of: Callable, title: str, notes: str) -> TableSpec:
    """A calibration table: per method (rows) the quantities (columns) of its fit."""
    return TableSpec(
        stem,
        lambda study: quantity_records(fits_of(study), quantities),
        index=("method",),
        columns=("source", "quantity", "unit"),
        labels={(q.source, q.quantity, q.unit): q.label for q in quantities},
        title=title,
        notes=notes,
    )


@dataclass(frozen=True)
class Calibration:
    """The results of the calibration: the constant noise model's fits per method
    (`calibrate_measurement_noise`), the geometric fit's floors (`calibrate_fit_floor`)."""

    fits: dict[str, dict]
    floor: dict


TABLES = (
    _table(
        "noise_calibration",
        NOISE_QUANTITIES,
        lambda study: study.fits,
        "Constant measurement-noise model: maximum-likelihood fits (tree park)",
        f"Seeds {list(SEEDS)}, 240 scans each on paths varied as in experiment 2, circles "
        "whose beams with a return mostly hit one trunk. sigma_range = a + b r, "
        "sigma_bearing^2 = c^2 + (t / r)^2. 'in use' is "
        "the cycab preset's constant models (the fits rounded up to two digits). A normalised "
        "variance of 1 means the fitted model matches the errors. 'range mean / filter "
        "sigma': the mean range error in units of the sigma the filter gives each circle "
        "(the cycab preset: the constant model in use, the geometric fit's "
        "covariance with its floors). 'fitted range bias': the line a + b r through the "
        "range errors by maximum likelihood under those sigmas (least squares weighted by "
        "1 / sigma^2, experiments/paper/calibration.py range_bias_line); 'in use': "
        "the cycab preset's range biases (the fits rounded to 0.1 mm and 0.01 mm per m), "
        "subtracted from the ranges in slam.run_slam.",
    ),
    _table(
        "noise_calibration_floor",
        FLOOR_QUANTITIES,
        lambda study: {"geometric": study.floor},
        "Floors of the geometric fit's covariance: maximum-likelihood fit (tree park)",
        f"Seeds {list(SEEDS)}, the circles of noise_calibration.md. R = R_fit + diag(f_r^2, "
        "f_b^2) fitted by maximum likelihood of the centre errors; 'in use' is "
        "the cycab preset's measurement.fit_floor_range_m and "
        "fit_floor_bearing_rad (the fits rounded up to two digits).",
    ),
)


@experiment(
    "noise-calibration",
    order=90,
    page="consistency.md",
    help="measurement-noise model of each extractor",
)
def run(ctx) -> None:
    """The registered experiment `noise-calibration`: the fits beside the values in use."""
    fits = calibrate_measurement_noise(executor=ctx.executor)
    ctx.config["noise-calibration"] = {"seeds": list(SEEDS), "scene": "tree_park"}
    floor = calibrate_fit_floor()
    ctx.config["noise-calibration"]["fit_floor"] = floor
    products.tables(ctx, TABLES, Calibration(fits, floor))

"""Experiment 2 of the paper: EKF-SLAM in a tree park with a car-like vehicle (Tables 3 and 4,
Figs. 7, 10, 11), plus filter consistency (NEES, NIS), and the `trunkslam slam` command.

Set-up (the paper's section 3, second experiment, replicated in simulation):
  scene      experiments/scenes/tree_park.json: eight tall trees, building walls, bushes (Fig. 6)
  vehicle    a Cycab-like car (`experiments.sim.trajectory.CycabParams`): wheelbase 1.2 m, SICK
             LMS200 at the front, 20 Hz odometry with speed and steering noise, 5 Hz scans,
             DGPS 2 cm at 10 Hz; 240 scans per run around a 57 m loop
  methods    circles from `paper` (modified Gauss-Newton), `geometric` (orthogonal fit with
             covariance) and `bailey` (the Victoria Park detector), all associated by IHGR
  Monte Carlo  50 runs (5 with --quick), each a fresh simulation (odometry noise, scan noise,
             mixed returns); the three methods see the same scans in a run.

The study (`monte_carlo`) gives the runs' figures (`Exp2Results`); the report (`report`) writes
from them alone the tables declared in `TABLES`, the figures and the key figures.

Writes (into ctx.out_dir)
  table3.md/.csv        average absolute pose error (the paper's formula), mean and spread over
                        the runs, beside the paper's numbers
  table4.md/.csv        false-detection rate for scans 10-40, 50-80, 90-120, 130-160
  consistency.md/.csv   NEES of the vehicle pose and NIS, per method, against 95% bounds
  fig7_slam_path.png    true and estimated path with the trees (run 0, paper features)
  fig10_innovations.png range and bearing innovations with 3 sigma (run 0, paper vs Bailey)
  fig11_pose_errors.png pose errors with 3 sigma (run 0, paper vs Bailey)
  nees.png              average NEES per scan, every method, with its bounds
  slam.rrd              rerun recording of run 0 with paper features (timeline `scan`)

Definitions
  pose error      estimate after the scan's update minus the truth at the scan time (rear-axle
                  centre; heading wrapped). Table 3: mean over the scans of |dx|, |dy|, |dtheta|
                  per run (the paper's formula), then mean and standard deviation over the runs.
  false feature   a circle whose beams (those with a return) do not mostly hit one trunk, or
                  whose centre, placed in the world with the true pose, lies more than
                  `false_match_m` (0.5 m) from that trunk's centre. Table 4: false / detected,
                  summed over the scans of the set and over the runs.
  NEES            e^T P^-1 e of the pose (3 dof) at each scan but the first (where the state is
                  the truth with zero covariance), averaged over the runs; 95% bounds
                  chi2_(3R)(0.025, 0.975) / R (docs/method.md section 5).
  NIS             per scan, the batch NIS summed over the runs against chi2 of the summed
                  degrees of freedom, and the overall NIS per degree of freedom.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import SimpleNamespace
from typing import NamedTuple

import numpy as np

from experiments.eval.detections import dominant_label, false_detections, run_labels
from experiments.eval.gospa import GOSPA_COLUMNS, GOSPA_LABELS, gospa_columns
from experiments.eval.poses import consistency as consistency_figures
from experiments.eval.poses import nees, nees_bounds, pose_errors
from experiments.eval.series import slam_panels, slam_series
from experiments.exec import SerialExecutor, spawn_seeds
from experiments.io.config_file import config_toml, load_slam_config
from experiments.io.writers import dumps_json, json_types, write_atomic
from experiments.paper import products
from experiments.paper.products import FigureSpec, TableSpec
from experiments.paper.registry import experiment
from experiments.sim import sensor_preset
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import SlamConfig, interpolate_poses, run_slam, se2
from slam.smoother import problem_from_log, smooth

__all__ = [
    "CYCAB_SLAM",
    "METHODS",
    "PAPER_TABLE3",
    "PAPER_TABLE4",
    "SCAN_SETS",
    "TABLES",
    "Exp2Config",
    "Exp2Results",
    "consistency",
    "consistency_records",
    "extractor_params",
    "key_figures",
    "monte_carlo",
    "recording_trial",
    "report",
    "run",
    "slam_trial",
    "table3_records",
    "table4_rates",
    "table4_records",
]

log = logging.getLogger(__name__)

METHODS = ("paper", "geometric", "bailey")
# The paper's Table 3 (m, m, rad) and Table 4.
PAPER_TABLE3 = {"paper": (0.0575, 0.0571, 0.0353), "bailey": (0.0823, 0.0732, 0.0528)}
PAPER_TABLE4 = {"paper": (0.067, 0.034, 0.067, 0.1), "bailey": (0.034, 0.067, 0.034, 0.067)}
QUANTITIES3 = (("dx", "m"), ("dy", "m"), ("dtheta", "rad"))  # Table 3's rows, with their units
SCAN_SETS = ((10, 40), (50, 80), (90, 120), (130, 160))  # inclusive, as the paper's Table 4
STYLE = {"paper": "-.", "geometric": "--", "bailey": "-"}

# The filter's model of the simulated Cycab (`CycabParams`): the `cycab` preset
# (experiments/presets/cycab.toml, which says what it holds and why). Its odometry noise is
# exactly as simulated (0.1 m/s and 2 deg per 20 Hz sample) with no pose floor: `OdometryNoise`'s
# default floor (1 mm and 0.1 mrad per sqrt(s)) stands for slip and keeps the covariance
# non-singular at rest on real data; the simulated car does not slip and stands still only
# before its first scan, so there the floor would only make the filter cautious where the true
# errors are smallest. Measured on calibration seeds (docs/notebook.md): the floor held the pose
# NEES of dead reckoning at 2.66 over scans 1-20 (2.98 without), and of the filter with ideal
# Gaussian centres at 2.69 over the run (2.94 without). The extractor is the paper's
# (`features.PAPER_FAITHFUL`: no short trunks), as the paper's tables were made with it; the
# measurement model is the simulated tree park's calibration (`noise-calibration`).
CYCAB_SLAM = load_slam_config("cycab")


@dataclass(frozen=True)
class Exp2Config:
    """Everything experiment 2 depends on.

    n_runs: Monte Carlo runs (50, the usual count for NEES; docs/method.md section 5).
    cycab: the simulated car, sensors and drive; by default each run's true path varies
        (`experiments.sim.trajectory.MONTE_CARLO_PATH`), so that the runs are independent.
        association: "ihgr" (the paper's), "jcbb", "nn".
    slam: the filter's configuration (measurement noise per method, map policy, ...); by
        default `CYCAB_SLAM`, the `cycab` preset.
    false_match_m: a circle on a trunk's beams farther than this from its centre is false.
    sensitivity: also run the consistency variants listed in `SENSITIVITY`, on the first
        `sensitivity_runs` runs (fewer than n_runs to keep the default under 3 minutes).
    smoother: also solve every run with the GTSAM smoother (`slam.smoother`, batch, from the
        run's own log: same odometry, measurements and associations) for its pose errors and
        NEES.
    """

    n_runs: int = 50
    methods: tuple[str, ...] = METHODS
    scene: str = "tree_park"
    cycab: CycabParams = field(default_factory=lambda: CycabParams(**MONTE_CARLO_PATH))
    association: str = "ihgr"
    slam: SlamConfig = field(default_factory=lambda: CYCAB_SLAM)
    false_match_m: float = 0.5
    sensitivity: bool = True
    sensitivity_runs: int = 20
    smoother: bool = True

    @classmethod
    def quick(cls) -> Exp2Config:
        """The small version (tests, golden numbers): 4 runs of 170 scans, no variants."""
        return cls(n_runs=4, cycab=CycabParams(n_scans=170, **MONTE_CARLO_PATH), sensitivity=False)


# Consistency variants: (name, method, SlamConfig overrides, kind). They explain the NEES figures:
# each switches off one part of the measurement model (the `cycab` preset's range biases and
# fit floors) or changes the detections. kind "synthetic": the method's circles on
# trunks only, each centre replaced by the truth plus Gaussian noise drawn from the method's
# constant noise model (same detections, ideal errors, no bias to correct); "": as extracted.
NO_PAPER_BIAS = {"measurement.range_bias": {"paper": [0.0, 0.0]}}
SENSITIVITY = (
    (  # the synthetic centres' noise is the constant model's, so the filter is told that one
        "paper detections, synthetic centres",
        "paper",
        {**NO_PAPER_BIAS, "measurement.noise": "constant"},
        "synthetic",
    ),
    ("paper, without the range-bias correction", "paper", NO_PAPER_BIAS, ""),
    ("paper, constant noise instead of the fit's", "paper", {"measurement.noise": "constant"}, ""),
    (
        "geometric, without the fit floors",
        "geometric",
        {"measurement.fit_floor_range_m": 0.0, "measurement.fit_floor_bearing_rad": 0.0},
        "",
    ),
    (
        "geometric, constant noise instead of the fit's",
        "geometric",
        {"measurement.noise": "constant"},
        "",
    ),
    (
        "bailey, without the range-bias correction",
        "bailey",
        {"measurement.range_bias": {"bailey": [0.0, 0.0]}},
        "",
    ),
    ("bailey, circles beyond 12 m ignored", "bailey", {"measurement.max_range_m": 12.0}, ""),
)


def extractor_params(method: str, cycab: CycabParams) -> dict:
    """Extractor parameters: the paper's and geometric extractors assume the simulated sensor's
    noise (range sigma with 1 cm quantisation, as the `features` experiment does) and are
    paper-faithful (`features.PAPER_FAITHFUL`: no short trunks, as `CYCAB_SLAM`)."""
    if method == "bailey":
        return {}
    s = sensor_preset(cycab.sensor, range_sigma_m=cycab.range_sigma_m)
    return {"sigma_r_m": s.effective_sigma_m, "short_trunks": False}


def run_config(cfg: Exp2Config, method: str) -> SlamConfig:
    """The whole configuration of experiment 2's filter for `method`: `cfg.slam` with the
    method, its extractor's parameters (`extractor_params`) and the association."""
    changes = {f"features.extractor.{k}": v for k, v in extractor_params(method, cfg.cycab).items()}
    changes |= {"features.method": method, "association.method": cfg.association}
    return cfg.slam.with_(**changes)


def synthetic_features(
    feats: list,
    seq,
    laser_w: np.ndarray,
    model,
    rng: np.random.Generator,
    false_match_m: float = 0.5,
) -> list:
    """The circles of `feats` that are true trunk detections, with their centres replaced by the
    true centre plus noise from the constant noise model `model` (s_r, s_r_per_m, s_b, s_t)."""
    s_r, s_rm, s_b, s_t = model
    lm = seq.truth_landmarks
    out = []
    for k, f in enumerate(feats):
        lw = laser_w[k]
        params = []
        labels = seq.scan_labels[k]
        for (a, b), p in zip(f.circle_beams, f.circle_params):
            one = SimpleNamespace(
                n_circles=1, circle_beams=np.array([[a, b]]), circle_params=np.array([p])
            )
            if false_detections(one, labels, lw, lm, false_match_m)[1]:
                continue
            j = dominant_label(run_labels(labels, a, b), returns_only=True)[0]
            d = lm[j, :2] - lw[:2]
            r = float(np.hypot(*d))
            bearing = math.atan2(d[1], d[0]) - lw[2]
            r += (s_r + s_rm * r) * rng.standard_normal()
            bearing += math.sqrt(s_b**2 + (s_t / r) ** 2) * rng.standard_normal()
            params.append([r * math.cos(bearing), r * math.sin(bearing), p[2]])
        n = len(params)
        out.append(
            replace(
                f,
                circle_params=np.array(params).reshape(n, 3),
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    return out


@dataclass
class Exp2Results:
    """Per-run figures, by method (or sensitivity variant name). R runs of N scans.

    abs_err (R, 3): the run's mean |dx|, |dy|, |dtheta|. nees (R, N): NaN at scan 0.
    nis, nis_dof (R, N): batch NIS of each scan and its dof (0: no update). detected, false
    (R, N): circles per scan. map_size, map_on_trees (R,): final landmarks, and how many lie
    within false_match_m of a tree. gospa: {GOSPA_COLUMNS name: (R,)} the final map's GOSPA
    against all the scene's trees (`experiments.eval.gospa.gospa_columns`). time_slam,
    time_extract (R,): mean seconds per scan.
    logs0: the SlamLog of run 0 per method; seq0: run 0's sequence.
    sm_abs_err (R, 3), sm_nees (R, N), time_smoother (R,): the same for the GTSAM smoother of
    each run (empty when `config.smoother` is off); sm_pose0: its path of run 0 per method.
    """

    config: Exp2Config
    abs_err: dict = field(default_factory=dict)
    nees: dict = field(default_factory=dict)
    nis: dict = field(default_factory=dict)
    nis_dof: dict = field(default_factory=dict)
    detected: dict = field(default_factory=dict)
    false: dict = field(default_factory=dict)
    map_size: dict = field(default_factory=dict)
    map_on_trees: dict = field(default_factory=dict)
    gospa: dict = field(default_factory=dict)
    time_slam: dict = field(default_factory=dict)
    time_extract: dict = field(default_factory=dict)
    logs0: dict = field(default_factory=dict)
    sm_abs_err: dict = field(default_factory=dict)
    sm_nees: dict = field(default_factory=dict)
    time_smoother: dict = field(default_factory=dict)
    sm_pose0: dict = field(default_factory=dict)
    seq0: object = None
    seconds: float = 0.0


def _variants(cfg: Exp2Config) -> list[tuple]:
    """(name, method, SlamConfig overrides, kind) of every row: the methods, then the
    sensitivity variants of the methods run."""
    variants = [(m, m, {}, "") for m in cfg.methods]
    if cfg.sensitivity:
        variants += [v for v in SENSITIVITY if v[1] in cfg.methods]
    return variants


def _runs_of(cfg: Exp2Config, name: str) -> int:
    return cfg.n_runs if name in cfg.methods else min(cfg.sensitivity_runs, cfg.n_runs)


def slam_trial(job: tuple[Exp2Config, int, bool], seed) -> dict:
    """Run r of the Monte Carlo study (`job` = (cfg, r, keep)), a pure function of its seed:
    one simulated drive, every method and variant on it. Returns per variant name the run's
    figures (abs_err, nees, nis, nis_dof, detected, false, map_size, map_on_trees, times,
    smoother's), and when `keep` also its sequence and logs (run 0: the figures, the
    recording)."""
    cfg, r, keep = job
    rng = np.random.default_rng(seed)
    variants = [v for v in _variants(cfg) if r < _runs_of(cfg, v[0])]
    seq = simulate_cycab_run(rng, cfg.scene, cfg.cycab)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    laser_w = np.array([se2.compose(p, seq.laser_pose) for p in truth])
    lm = seq.truth_landmarks
    out: dict = {"time_extract": {}, "runs": {}}
    feats: dict[str, list] = {}
    for m in sorted({v[1] for v in variants}):
        t0 = time.perf_counter()
        params, options = run_config(cfg, m).features.extractor_args()
        feats[m] = [extract_features(seq.scan(k), m, params, **options) for k in range(seq.n_scans)]
        out["time_extract"][m] = (time.perf_counter() - t0) / seq.n_scans
    noise_rng = rng.spawn(1)[0]
    for name, m, overrides, kind in variants:
        scfg = run_config(cfg, m).with_(**overrides)
        fs = feats[m]
        if kind == "synthetic":
            model = scfg.measurement.model_for(m).constant
            fs = synthetic_features(
                fs, seq, laser_w, model, noise_rng, false_match_m=cfg.false_match_m
            )
        lg = run_slam(seq, scfg, features=fs)
        # the filter's own time per scan (`slam.run_slam` warms up before it times the scans)
        o: dict = {"time_slam": float(np.mean(lg.timing_s["total"]))}
        e = pose_errors(lg.pose, truth)
        # the paper's formula, over the scans after the first (which starts at the truth)
        o["abs_err"] = np.mean(np.abs(e[1:]), axis=0)
        o["nees"] = nees(e[1:], lg.pose_cov[1:])
        o["nis"] = lg.scan_nis
        o["nis_dof"] = lg.scan_nis_dof
        if cfg.smoother:
            sm = smooth(problem_from_log(lg))
            es = pose_errors(sm.pose, truth)
            o["sm_abs_err"] = np.mean(np.abs(es[1:]), axis=0)
            o["sm_nees"] = nees(es[1:], sm.pose_cov[1:])
            o["time_smoother"] = sm.seconds + sm.seconds_marginals
            if keep and name == m:
                o["sm_pose0"] = sm.pose
        if name == m:
            det = [
                false_detections(f, seq.scan_labels[k], laser_w[k], lm, cfg.false_match_m)
                for k, f in enumerate(feats[m])
            ]
            o["detected"] = np.array([d for d, _ in det], np.int64)
            o["false"] = np.array([f for _, f in det], np.int64)
        o["map_size"] = lg.landmark_xy.shape[0]
        o["map_on_trees"] = 0
        if lg.landmark_xy.shape[0]:
            d = np.hypot(
                lg.landmark_xy[:, None, 0] - lm[None, :, 0],
                lg.landmark_xy[:, None, 1] - lm[None, :, 1],
            )
            o["map_on_trees"] = int(np.sum(d.min(axis=1) <= cfg.false_match_m))
        o["gospa"] = gospa_columns(lg.landmark_xy, lm[:, :2])
        if keep and name == m:
            o["log0"] = lg
        out["runs"][name] = o
    if keep:
        out["seq0"] = seq
    return out


def monte_carlo(
    cfg: Exp2Config, rng: np.random.Generator, progress=None, executor=None
) -> Exp2Results:
    """Run the Monte Carlo study; `rng` seeds every run (run i uses rng.spawn(n_runs)[i], as
    `spawn_seeds(rng, n_runs)[i]`). The runs are trials (`slam_trial`) on `executor` (default:
    this process), reduced in run order."""
    t_start = time.perf_counter()
    res = Exp2Results(cfg)
    variants = _variants(cfg)
    N = cfg.cycab.n_scans
    for name, *_ in variants:
        R = _runs_of(cfg, name)
        res.abs_err[name] = np.zeros((R, 3))
        for d in (res.nees, res.nis):
            d[name] = np.full((R, N), np.nan)
        res.nis_dof[name] = np.zeros((R, N), np.int64)
        for d in (res.detected, res.false):
            d[name] = np.zeros((R, N), np.int64)
        for d in (res.map_size, res.map_on_trees):
            d[name] = np.zeros(R, np.int64)
        res.gospa[name] = {k: np.zeros(R) for k in GOSPA_COLUMNS}
        res.time_slam[name] = np.zeros(R)
        res.time_extract[name] = np.zeros(R)
        if cfg.smoother:
            res.sm_abs_err[name] = np.zeros((R, 3))
            res.sm_nees[name] = np.full((R, N), np.nan)
            res.time_smoother[name] = np.zeros(R)
    R = cfg.n_runs
    executor = executor or SerialExecutor()
    records = executor.map(
        slam_trial,
        [(cfg, r, r == 0) for r in range(R)],
        spawn_seeds(rng, R),
        desc="table3/4 Monte Carlo",
        progress=progress,
        chunksize=1,
    )
    for r, rec in enumerate(records):
        for m, t in rec["time_extract"].items():
            res.time_extract[m][r] = t
        for name, o in rec["runs"].items():
            res.time_slam[name][r] = o["time_slam"]
            res.abs_err[name][r] = o["abs_err"]
            res.nees[name][r, 1:] = o["nees"]
            res.nis[name][r] = o["nis"]
            res.nis_dof[name][r] = o["nis_dof"]
            if cfg.smoother:
                res.sm_abs_err[name][r] = o["sm_abs_err"]
                res.sm_nees[name][r, 1:] = o["sm_nees"]
                res.time_smoother[name][r] = o["time_smoother"]
                if "sm_pose0" in o:
                    res.sm_pose0[name] = o["sm_pose0"]
            if "detected" in o:
                res.detected[name][r], res.false[name][r] = o["detected"], o["false"]
            res.map_size[name][r] = o["map_size"]
            res.map_on_trees[name][r] = o["map_on_trees"]
            for k in GOSPA_COLUMNS:
                res.gospa[name][k][r] = o["gospa"][k]
            if "log0" in o:
                res.logs0[name] = o["log0"]
        if r == 0:
            res.seq0 = rec["seq0"]
    res.seconds = time.perf_counter() - t_start
    return res


# ---- tables -------------------------------------------------------------------------------------


def consistency(res: Exp2Results, name: str) -> dict:
    """NEES and NIS figures of one method or variant (`experiments.eval.poses.consistency`)."""
    return consistency_figures(res.nees[name], res.nis[name], res.nis_dof[name])


def _smoother_nees(res: Exp2Results, name: str) -> dict:
    if not res.sm_nees:
        return {}
    c = consistency_figures(res.sm_nees[name], res.nis[name], res.nis_dof[name])
    return {"smoother_nees_mean": c["nees_mean"], "smoother_nees_in_bounds": c["nees_in"]}


def table4_rates(res: Exp2Results, method: str) -> list[float]:
    """The paper's false-detection rate: per scan, false features / detected features; averaged
    over the scans of each set (indices as the paper's scan numbers, inclusive) that have a
    detection, over all runs."""
    out = []
    for a, b in SCAN_SETS:
        det = res.detected[method][:, a : b + 1]
        fal = res.false[method][:, a : b + 1]
        has = det > 0
        out.append(float(np.mean(fal[has] / det[has])) if has.any() else math.nan)
    return out


def key_figures(res: Exp2Results) -> dict:
    """The figures kept as golden numbers (plain JSON types)."""
    out: dict = {"n_runs": res.config.n_runs, "n_scans": res.config.cycab.n_scans}
    for m in res.config.methods:
        c = consistency(res, m)
        out[m] = {
            "table3_mean": [round(float(v), 6) for v in res.abs_err[m].mean(axis=0)],
            "table4": [round(v, 6) if math.isfinite(v) else None for v in table4_rates(res, m)],
            "nees_mean": round(c["nees_mean"], 4),
            "nis_per_dof": round(c["nis_per_dof"], 4),
            "map_size_mean": float(res.map_size[m].mean()),
            "map_on_trees_mean": float(res.map_on_trees[m].mean()),
        }
        if res.sm_abs_err:
            out[m]["smoother_table3_mean"] = [
                round(float(v), 6) for v in res.sm_abs_err[m].mean(axis=0)
            ]
            out[m]["smoother_nees_mean"] = round(float(np.nanmean(res.sm_nees[m])), 4)
    return out


class _Table3Column(NamedTuple):
    """A column of Table 3: its key (source, method, estimator, statistic), its header, and its
    values, one per row of `QUANTITIES3` (dx, dy, dtheta)."""

    key: tuple[str, str, str, str]
    label: str
    values: Sequence[float]


def _table3_columns(res: Exp2Results) -> list[_Table3Column]:
    """Per method the EKF's mean and spread over the runs (and the smoother's mean), then the
    paper's published means."""
    cols = []
    for m in res.config.methods:
        e = res.abs_err[m]
        mean = [e[:, i].mean() for i in range(3)]
        std = [e[:, i].std(ddof=1) if res.config.n_runs > 1 else math.nan for i in range(3)]
        cols.append(_Table3Column(("simulation", m, "ekf", "mean"), f"{m} mean", mean))
        cols.append(_Table3Column(("simulation", m, "ekf", "std"), f"{m} std", std))
        if res.sm_abs_err:
            sm = [res.sm_abs_err[m][:, i].mean() for i in range(3)]
            cols.append(
                _Table3Column(("simulation", m, "smoother", "mean"), f"{m} smoother mean", sm)
            )
    for m, label in (("paper", "paper's proposed"), ("bailey", "paper's Bailey")):
        cols.append(_Table3Column(("paper_published", m, "ekf", "mean"), label, PAPER_TABLE3[m]))
    return cols


def table3_records(res: Exp2Results) -> list[dict]:
    """Table 3 as tidy records: source, method, estimator, quantity, unit, statistic, value."""
    return [
        {
            "source": source,
            "method": method,
            "estimator": estimator,
            "quantity": q,
            "unit": unit,
            "statistic": statistic,
            "value": float(v),
        }
        for (source, method, estimator, statistic), _, values in _table3_columns(res)
        for (q, unit), v in zip(QUANTITIES3, values)
    ]


def _table3_notes(res: Exp2Results) -> str:
    cfg = res.config
    mean = {m: res.abs_err[m].mean(axis=0) for m in cfg.methods}
    notes = [
        (
            f"{cfg.n_runs} Monte Carlo runs of {cfg.cycab.n_scans} scans (scene {cfg.scene}, "
            f"association {cfg.association}); per run the mean over the scans after the first of "
            "|dx|, |dy|, |dtheta| (the paper's formula, pose after each scan's update), then the "
            "mean and the standard deviation over the runs. The reference is the simulated EXACT "
            "pose, not the simulated 2 cm DGPS: scoring x, y against a 2 cm DGPS would add its "
            "own noise (mean |error| of 2 cm Gaussian noise: 0.016 m per axis), as large as the "
            "errors here. The paper's numbers are one real run against a real DGPS."
        )
    ]
    if "paper" in mean and "bailey" in mean:
        lower = [bool(mean["paper"][i] < mean["bailey"][i]) for i in range(3)]
        notes.append(f"Direction as the paper (paper < bailey in dx, dy, dtheta): {lower}.")
    if "paper" in mean and "geometric" in mean:
        geo = [bool(mean["geometric"][i] <= mean["paper"][i]) for i in range(3)]
        notes.append(f"geometric <= paper in dx, dy, dtheta: {geo}.")
    if res.sm_abs_err:
        below = {
            m: [bool(res.sm_abs_err[m][:, i].mean() <= mean[m][i]) for i in range(3)]
            for m in cfg.methods
        }
        notes.append(
            "smoother: the GTSAM smoother of each run (`slam.smoother`, batch Levenberg-"
            "Marquardt) with the run's own odometry, measurements and associations; its pose at "
            "each scan uses the whole run, the EKF's only the scans up to it. Smoother <= EKF in "
            f"dx, dy, dtheta: {below}."
        )
    return "\n\n".join(notes)


def table4_records(res: Exp2Results) -> list[dict]:
    """Table 4 as tidy records: per source and method the false-detection rate of each scan
    set, and (simulation) the circles per scan over the whole run."""
    cfg = res.config
    last = cfg.cycab.n_scans - 1
    out: list[dict] = []
    for source, method, rates, circles in (
        *(
            ("simulation", m, table4_rates(res, m), float(res.detected[m].mean()))
            for m in cfg.methods
        ),
        ("paper_published", "paper", PAPER_TABLE4["paper"], None),
        ("paper_published", "bailey", PAPER_TABLE4["bailey"], None),
    ):
        ident = {"source": source, "method": method}
        out += [
            {
                **ident,
                "quantity": "false_detection_rate",
                "first_scan": a,
                "last_scan": b,
                "unit": "fraction",
                "value": v,
            }
            for (a, b), v in zip(SCAN_SETS, rates)
        ]
        if circles is not None:
            out.append(
                {
                    **ident,
                    "quantity": "circles_per_scan",
                    "first_scan": 0,
                    "last_scan": last,
                    "unit": "count",
                    "value": circles,
                }
            )
    return out


def _table4_labels(res: Exp2Results) -> dict:
    labels: dict = {
        ("false_detection_rate", a, b, "fraction"): f"scans {a}-{b}" for a, b in SCAN_SETS
    }
    labels[("circles_per_scan", 0, res.config.cycab.n_scans - 1, "count")] = "circles per scan"
    return labels


def _table4_notes(res: Exp2Results) -> str:
    return (
        f"The paper's rate: false features / detected features in a scan, averaged over the "
        f"scans of each set that have a detection (scan indices from 0, the sets inclusive) "
        f"and the {res.config.n_runs} runs. A circle is false when the beams it was fitted to do "
        f"not mostly hit one trunk (per-beam truth labels: bushes, walls, mixed returns) or its "
        f"centre lies more than {res.config.false_match_m} m from that trunk's. The paper and "
        "geometric extractors find the same circles (they differ only in the fit), so their "
        "rates are equal."
    )


def consistency_records(res: Exp2Results) -> list[dict]:
    """The consistency table as tidy records: one per method or variant (NEES, NIS, the
    smoother's NEES, the map, the filter's time per scan)."""
    rows = []
    for name in res.nees:
        c = consistency(res, name)
        rows.append(
            {
                "method": name,
                "runs": res.nees[name].shape[0],
                "nees_mean": c["nees_mean"],
                "nees_in_bounds": c["nees_in"],
                "nees_below": c["nees_below"],
                "nees_above": c["nees_above"],
                "nees_bound_low": c["nees_lo"],
                "nees_bound_high": c["nees_hi"],
                "nis_per_dof": c["nis_per_dof"],
                "nis_in_bounds": c["nis_in"],
                **_smoother_nees(res, name),
                "landmarks": float(res.map_size[name].mean()),
                "landmarks_on_trees": float(res.map_on_trees[name].mean()),
                "ms_per_scan": 1e3 * float(res.time_slam[name].mean()),
                **{k: float(v.mean()) for k, v in res.gospa[name].items()},
            }
        )
    return rows


def _consistency_notes(res: Exp2Results) -> str:
    cfg = res.config
    notes = (
        "Vehicle-pose NEES (3 dof) averaged over the runs at each scan after the first; the "
        "fraction of scans where it lies inside its 95% chi-square bounds (target: at least "
        "0.9). NIS: per scan, the batch NIS summed over the runs against the chi-square bounds "
        "of the summed degrees of freedom; NIS per dof is the overall ratio (1 when "
        "consistent). Landmarks: final map size (mean over runs), and how many lie within "
        f"{cfg.false_match_m} m of a tree; GOSPA (p = 2, alpha = 2; c = 1 m and the RFS-SLAM "
        "papers' c = 20 m) of the final map against all the scene's trees, mean over runs, "
        "with its localisation, missed and false parts in m^2 (in each run they add up to its "
        "square; experiments/eval/gospa.py). ms per scan: the filter alone (prediction, "
        "association, update, map management), features extracted beforehand. Rows after the "
        "three methods are variants that explain the figures (docs/experiments/consistency.md), "
        "on the first "
        f"{cfg.sensitivity_runs} runs."
    )
    if res.sm_nees:
        notes += (
            " Smoother NEES: the same statistic for the GTSAM smoother's poses with their "
            "marginal covariances (same runs, same associations)."
        )
    return notes


TABLES = (
    TableSpec(
        "table3",
        table3_records,
        index=("quantity", "unit"),
        columns=("source", "method", "estimator", "statistic"),
        labels=lambda res: {c.key: c.label for c in _table3_columns(res)},
        title="Table 3: average absolute pose error",
        notes=_table3_notes,
    ),
    TableSpec(
        "table4",
        table4_records,
        index=("source", "method"),
        columns=("quantity", "first_scan", "last_scan", "unit"),
        labels=_table4_labels,
        title="Table 4: false-detection rate",
        notes=_table4_notes,
    ),
    TableSpec(
        "consistency",
        consistency_records,
        index=("method",),
        values=None,
        labels={
            "nees_mean": "NEES mean",
            "nees_in_bounds": "NEES in 95% bounds",
            "nees_below": "below",
            "nees_above": "above",
            "nees_bound_low": "bound low",
            "nees_bound_high": "bound high",
            "nis_per_dof": "NIS per dof",
            "nis_in_bounds": "NIS in 95% bounds",
            "smoother_nees_mean": "smoother NEES mean",
            "smoother_nees_in_bounds": "smoother NEES in 95% bounds",
            "landmarks_on_trees": "on trees",
            "ms_per_scan": "ms per scan",
            **GOSPA_LABELS,
        },
        title="Consistency of the EKF (NEES, NIS)",
        notes=_consistency_notes,
    ),
)


# ---- figures and recording ----------------------------------------------------------------------


def _tree_of_landmarks(lg, lm: np.ndarray, tol: float) -> dict[int, int]:
    out = {}
    for lid, xy in zip(lg.landmark_id, lg.landmark_xy):
        d = np.hypot(*(lm[:, :2] - xy).T)
        if d.min() <= tol:
            out[int(lid)] = int(np.argmin(d))
    return out


def _figure_specs(res: Exp2Results) -> list[FigureSpec]:
    """Figs. 7, 10, 11 and the NEES figure: (file name, plot function, arguments, keyword
    arguments) each, drawn on the executor (`experiments.paper.products`). Figs. 10 and 11
    compare the paper's features with Bailey's (the methods run, when not both)."""
    from experiments.sim import load_scene

    seq = res.seq0
    scene = load_scene(res.config.scene)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    pair = [m for m in ("paper", "bailey") if m in res.logs0] or list(res.logs0)
    return [
        _fig7_path(res, scene, truth),
        _fig10_innovations(res, scene, pair),
        _fig11_pose_errors(res, truth, pair),
        _nees_figure(res),
    ]


def _fig7_path(res: Exp2Results, scene, truth: np.ndarray) -> FigureSpec:
    """Fig. 7: the true and estimated path of run 0 with the trees (paper features)."""
    from experiments.paper import slam_figures

    main = "paper" if "paper" in res.logs0 else next(iter(res.logs0))
    lg = res.logs0[main]
    title = f"Fig. 7: true (dashed) and estimated path, {main} features, IHGR (run 0)"
    args = (
        truth[:, :2],
        lg.pose[:, :2],
        res.seq0.truth_landmarks,
        lg.landmark_xy,
        lg.landmark_cov,
        title,
    )
    walls = [w.points_xy for w in scene.walls]
    bushes = [b.points_xy for b in scene.bushes]
    return (
        "fig7_slam_path.png",
        slam_figures.plot_slam_path,
        args,
        {"walls": walls, "bushes": bushes},
    )


def _most_observed_tree(res: Exp2Results, methods: list[str]) -> tuple[int | None, dict]:
    """(the tree observed most often by every one of `methods` in run 0, or None; per method
    {landmark id: its tree})."""
    lm = res.seq0.truth_landmarks
    trees = {m: _tree_of_landmarks(res.logs0[m], lm, res.config.false_match_m) for m in methods}
    counts: dict = {}
    for m in methods:
        lgm = res.logs0[m]
        for lid, j in trees[m].items():
            counts.setdefault(j, {})[m] = int(np.sum(lgm.obs_landmark == lid))
    if not counts:
        return None, trees
    return max(counts, key=lambda j: min(counts[j].get(m, 0) for m in methods)), trees


def _fig10_innovations(res: Exp2Results, scene, pair: list[str]) -> FigureSpec:
    """Fig. 10: range and bearing innovations with 3 sigma of the tree observed most often by
    both methods (run 0)."""
    from experiments.paper import slam_figures

    best, trees = _most_observed_tree(res, pair)
    series = []
    for m in pair:
        lgm = res.logs0[m]
        lids = [lid for lid, j in trees[m].items() if j == best]
        sel = np.isin(lgm.obs_landmark, lids)
        sig = np.sqrt(np.stack([lgm.obs_innov_cov[sel, 0, 0], lgm.obs_innov_cov[sel, 1, 1]], 1))
        series.append(
            {
                "label": m,
                "scan": lgm.obs_scan[sel],
                "innov": lgm.obs_innov[sel],
                "sigma": sig,
                "style": STYLE.get(m, "-"),
            }
        )
    name = scene.circles[best].name if best is not None else "-"
    title = f"Fig. 10: innovations of tree {name} with 3 sigma bounds (run 0)"
    return ("fig10_innovations.png", slam_figures.plot_innovations, (series, title), {})


def _fig11_pose_errors(res: Exp2Results, truth: np.ndarray, pair: list[str]) -> FigureSpec:
    """Fig. 11: the errors of the predicted pose with 3 sigma (run 0)."""
    from experiments.paper import slam_figures

    series = []
    for m in pair:
        lgm = res.logs0[m]
        e = pose_errors(lgm.pred_pose, truth)
        sig = np.sqrt(np.maximum(np.diagonal(lgm.pred_pose_cov, axis1=1, axis2=2), 0.0))
        series.append(
            {
                "label": m,
                "scan": np.arange(res.seq0.n_scans),
                "err": e,
                "sigma": sig,
                "style": STYLE.get(m, "-"),
            }
        )
    title = "Fig. 11: predicted pose errors with 3 sigma bounds (run 0)"
    return ("fig11_pose_errors.png", slam_figures.plot_pose_errors, (series, title), {})


def _nees_figure(res: Exp2Results) -> FigureSpec:
    """The average NEES per scan of every method, with its 95% bounds."""
    from experiments.paper import slam_figures

    cfg = res.config
    args = (
        {n: consistency(res, n)["nees_avg"] for n in cfg.methods},
        nees_bounds(cfg.n_runs),
        f"Average vehicle-pose NEES over {cfg.n_runs} runs",
        "NEES (3 dof, no unit)",
    )
    # consistency() leaves scan 0 out
    return ("nees.png", slam_figures.plot_consistency, args, {"expected": 3.0, "first_scan": 1})


def recording_trial(cfg: Exp2Config, seed) -> dict[str, bytes]:
    """slam.rrd, {file name: bytes}: run 0 of the Monte Carlo study (`seed`: its seed, so the
    same drive as `slam_trial`'s run 0) with the paper's features, recorded as it goes. A trial
    of its own, so that it runs on a worker beside the study's runs."""
    from experiments.render.viz import MemoryRecorder

    seq = simulate_cycab_run(np.random.default_rng(seed), cfg.scene, cfg.cycab)
    m = "paper" if "paper" in cfg.methods else cfg.methods[0]
    with MemoryRecorder("slam", series=slam_panels(True)) as rec:
        rec.log_truth_trees(seq.truth_landmarks)
        lg = run_slam(seq, run_config(cfg, m), visualiser=rec)
        rec.log_series(lg.scan_t, slam_series(lg, seq.truth_t, seq.truth_pose))
    return {"slam.rrd": rec.data}


# ---- the registered experiment ------------------------------------------------------------------


@experiment(
    "table3",
    "table4",
    order=40,
    page="slam.md",
    help="EKF-SLAM Monte Carlo on the simulated tree park (one run), with the GTSAM "
    "smoother's columns, slam.rrd",
)
def run(ctx, cfg: Exp2Config | None = None) -> Exp2Results:
    """Experiment 2 (registered as `table3` and `table4`, one run for both): Tables 3 and 4,
    Figs. 7, 10, 11, NEES/NIS and slam.rrd into ctx.out_dir."""
    cfg = cfg or (Exp2Config.quick() if ctx.quick else Exp2Config())
    ctx.config["table3"] = {
        "n_runs": cfg.n_runs,
        "methods": list(cfg.methods),
        "scene": cfg.scene,
        "association": cfg.association,
        "cycab": cfg.cycab.to_dict(),
        "slam": json_types(cfg.slam.to_dict()),
        "false_match_m": cfg.false_match_m,
        "extractor_params": {m: extractor_params(m, cfg.cycab) for m in cfg.methods},
        "sensitivity": [v[0] for v in SENSITIVITY] if cfg.sensitivity else [],
    }
    # the recording first, on a worker, beside the study's runs; written after the experiments
    run0 = spawn_seeds(ctx.rng("slam"), cfg.n_runs)[0]  # the seed monte_carlo gives run 0
    recording = ctx.submit(recording_trial, [cfg], [run0], desc="slam recording")
    ctx.later(recording, lambda got: products.write(ctx, got[0]))
    res = monte_carlo(cfg, ctx.rng("slam"), progress=ctx.progress, executor=ctx.executor)
    report(ctx, res)
    log.info("experiment 2: %d runs in %.1f s", cfg.n_runs, res.seconds)
    return res


def report(ctx, res: Exp2Results) -> None:
    """Experiment 2's files from its results: the tables (`TABLES`), the figures (drawn on the
    executor), the key figures, and each method's filter as a configuration file."""
    products.tables(ctx, TABLES, res)
    products.figures(ctx, _figure_specs(res), desc="slam figures")
    out = Path(ctx.out_dir)
    ctx.outputs.append(
        write_atomic(out / "slam_key_figures.json", dumps_json(json_types(key_figures(res))))
    )
    for m in res.config.methods:  # each method's filter, whole: `trunkslam slam RUN.npz --config`
        header = f"experiment 2 (Tables 3-4), {m}: the filter of every run of the study"
        write_atomic(
            ctx.path(f"table3_config_{m}.toml"), config_toml(run_config(res.config, m), header)
        )

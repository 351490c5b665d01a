"""Experiment 2 of the paper: EKF-SLAM in a tree park with a car-like vehicle (Tables 3 and 4,
Figs. 7, 10, 11), plus filter consistency (NEES, NIS), and the `trunkslam slam` command.

Set-up (the paper's section 3, second experiment, replicated in simulation):
  scene      datasets/scenes/tree_park.json: eight tall trees, building walls, bushes (Fig. 6)
  vehicle    a Cycab-like car (`experiments.sim.trajectory.CycabParams`): wheelbase 1.2 m, SICK
             LMS200 at the front, 20 Hz odometry with speed and steering noise, 5 Hz scans,
             DGPS 2 cm at 10 Hz; 240 scans per run around a 57 m loop
  methods    circles from `paper` (modified Gauss-Newton), `geometric` (orthogonal fit with
             covariance) and `bailey` (the Victoria Park detector), all associated by IHGR
  Monte Carlo  50 runs (5 with --quick), each a fresh simulation (odometry noise, scan noise,
             mixed returns); the three methods see the same scans in a run.

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
                  chi2_(3R)(0.025, 0.975) / R (METHOD_NOTES section 5).
  NIS             per scan, the batch NIS summed over the runs against chi2 of the summed
                  degrees of freedom, and the overall NIS per degree of freedom.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from experiments.export import dumps_json, write_atomic, write_table
from experiments.sim.trajectory import CycabParams, simulate_cycab_run
from features import extract_features
from slam import SlamConfig, interpolate_poses, wrap_angle
from slam import run as slam_run

__all__ = [
    "GOLDEN_PATH",
    "METHODS",
    "PAPER_TABLE3",
    "PAPER_TABLE4",
    "SCAN_SETS",
    "Exp2Config",
    "Exp2Results",
    "calibrate_measurement_noise",
    "extractor_params",
    "false_detections",
    "key_figures",
    "monte_carlo",
    "run_table3",
    "run_table4",
    "run_table34",
    "slam_command",
]

log = logging.getLogger(__name__)

METHODS = ("paper", "geometric", "bailey")
# The paper's Table 3 (m, m, rad) and Table 4.
PAPER_TABLE3 = {"paper": (0.0575, 0.0571, 0.0353), "bailey": (0.0823, 0.0732, 0.0528)}
PAPER_TABLE4 = {"paper": (0.067, 0.034, 0.067, 0.1), "bailey": (0.034, 0.067, 0.034, 0.067)}
SCAN_SETS = ((10, 40), (50, 80), (90, 120), (130, 160))  # inclusive, as the paper's Table 4
GOLDEN_PATH = Path(__file__).resolve().parent.parent / "tests" / "golden" / "exp_slam_quick.json"
STYLE = {"paper": "-.", "geometric": "--", "bailey": "-"}


@dataclass(frozen=True)
class Exp2Config:
    """Everything experiment 2 depends on.

    n_runs: Monte Carlo runs (50, the usual count for NEES; METHOD_NOTES section 5).
    cycab: the simulated car, sensors and drive. association: "ihgr" (the paper's), "jcbb", "nn".
    slam: the filter's configuration (measurement noise per method, map policy, ...).
    false_match_m: a circle on a trunk's beams farther than this from its centre is false.
    sensitivity: also run the consistency variants listed in `SENSITIVITY`, on the first
        `sensitivity_runs` runs (fewer than n_runs to keep the default under 3 minutes).
    """

    n_runs: int = 50
    methods: tuple[str, ...] = METHODS
    scene: str = "tree_park"
    cycab: CycabParams = field(default_factory=CycabParams)
    association: str = "ihgr"
    slam: SlamConfig = field(default_factory=SlamConfig)
    false_match_m: float = 0.5
    sensitivity: bool = True
    sensitivity_runs: int = 20

    @classmethod
    def quick(cls) -> Exp2Config:
        """The small version (tests, golden numbers): 4 runs of 170 scans, no variants."""
        return cls(n_runs=4, cycab=CycabParams(n_scans=170), sensitivity=False)


# Consistency variants: (name, method, SlamConfig overrides, kind). They explain the NEES figures.
# kind "synthetic": the method's circles on trunks only, each centre replaced by the truth plus
# Gaussian noise drawn from the method's constant noise model (same detections, ideal errors);
# "debias": every centre moved KASA_RANGE_BIAS_M farther along its beam; "": as extracted.
KASA_RANGE_BIAS_M = -0.0043  # mean range error of the paper's centres (calibration seeds)
SENSITIVITY = (
    ("paper detections, synthetic centres", "paper", {}, "synthetic"),
    ("paper, Kasa's mean range bias (4.3 mm) removed", "paper", {}, "debias"),
    (
        "geometric, constant noise instead of the fit's",
        "geometric",
        {"measurement_noise": "constant"},
        "",
    ),
    ("bailey, circles beyond 12 m ignored", "bailey", {"max_feature_range_m": 12.0}, ""),
)


def extractor_params(method: str, cycab: CycabParams) -> dict:
    """Extractor parameters: the paper's and geometric extractors assume the simulated sensor's
    noise (range sigma with 1 cm quantisation, as the `features` experiment does)."""
    if method == "bailey":
        return {}
    from experiments.sim.simulate import sensor_preset

    s = sensor_preset(cycab.sensor, range_sigma_m=cycab.range_sigma_m)
    return {"sigma_r_m": math.sqrt(s.range_sigma_m**2 + s.quantisation_m**2 / 12.0)}


def false_detections(
    features,
    labels: np.ndarray,
    laser_world_pose: np.ndarray,
    truth_landmarks: np.ndarray,
    false_match_m: float = 0.5,
) -> tuple[int, int]:
    """(detected, false) circles of one scan; see the module docstring for "false"."""
    n = int(features.n_circles)
    if n == 0:
        return 0, 0
    L = truth_landmarks.shape[0]
    c, s = math.cos(laser_world_pose[2]), math.sin(laser_world_pose[2])
    false = 0
    nb = labels.shape[0]
    for (a, b), p in zip(features.circle_beams, features.circle_params):
        idx = np.arange(int(a), int(b) + 1) % nb
        lab = labels[idx]
        lab = lab[lab >= 0]
        if lab.size == 0:
            false += 1
            continue
        counts = np.bincount(lab)
        j = int(np.argmax(counts))
        if j >= L or counts[j] * 2 <= lab.size:
            false += 1
            continue
        w = laser_world_pose[:2] + np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])
        if np.hypot(*(w - truth_landmarks[j, :2])) > false_match_m:
            false += 1
    return n, false


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
        nb = seq.scan_labels.shape[1]
        for (a, b), p in zip(f.circle_beams, f.circle_params):
            one = type(
                "One",
                (),
                {
                    "n_circles": 1,
                    "circle_beams": np.array([[a, b]]),
                    "circle_params": np.array([p]),
                },
            )()
            if false_detections(one, seq.scan_labels[k], lw, lm, false_match_m)[1]:
                continue
            lab = seq.scan_labels[k][np.arange(int(a), int(b) + 1) % nb]
            j = int(np.bincount(lab[lab >= 0]).argmax())
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


def _push_out(f, dr_m: float):
    """Features with every circle centre moved dr_m farther along its beam."""
    p = np.array(f.circle_params, dtype=np.float64).reshape(-1, 3)
    r = np.hypot(p[:, 0], p[:, 1])
    scale = np.where(r > 0, (r + dr_m) / np.where(r > 0, r, 1.0), 1.0)
    p[:, :2] *= scale[:, None]
    return replace(f, circle_params=p)


def _laser_world(pose: np.ndarray, laser: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array(
        [
            pose[0] + c * laser[0] - s * laser[1],
            pose[1] + s * laser[0] + c * laser[1],
            pose[2] + laser[2],
        ]
    )


@dataclass
class Exp2Results:
    """Per-run figures, by method (or sensitivity variant name). R runs of N scans.

    abs_err (R, 3): the run's mean |dx|, |dy|, |dtheta|. nees (R, N): NaN at scan 0.
    nis, nis_dof (R, N): batch NIS of each scan and its dof (0: no update). detected, false
    (R, N): circles per scan. map_size, map_on_trees (R,): final landmarks, and how many lie
    within false_match_m of a tree. time_slam, time_extract (R,): mean seconds per scan.
    logs0: the SlamLog of run 0 per method; seq0: run 0's sequence.
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
    time_slam: dict = field(default_factory=dict)
    time_extract: dict = field(default_factory=dict)
    logs0: dict = field(default_factory=dict)
    seq0: object = None
    seconds: float = 0.0


def monte_carlo(cfg: Exp2Config, rng: np.random.Generator, progress=None) -> Exp2Results:
    """Run the Monte Carlo study; `rng` seeds every run (run i uses rng.spawn(n_runs)[i])."""
    t_start = time.perf_counter()
    res = Exp2Results(cfg)
    variants = [(m, m, {}, "") for m in cfg.methods]
    if cfg.sensitivity:
        variants += [v for v in SENSITIVITY if v[1] in cfg.methods]
    R = cfg.n_runs
    N = cfg.cycab.n_scans
    runs_of = {v[0]: (R if v[0] in cfg.methods else min(cfg.sensitivity_runs, R)) for v in variants}
    for name, *_ in variants:
        R = runs_of[name]
        res.abs_err[name] = np.zeros((R, 3))
        for d in (res.nees, res.nis):
            d[name] = np.full((R, N), np.nan)
        res.nis_dof[name] = np.zeros((R, N), np.int64)
        for d in (res.detected, res.false):
            d[name] = np.zeros((R, N), np.int64)
        for d in (res.map_size, res.map_on_trees):
            d[name] = np.zeros(R, np.int64)
        res.time_slam[name] = np.zeros(R)
        res.time_extract[name] = np.zeros(R)
    R = cfg.n_runs
    gens = rng.spawn(R)
    for r in range(R):
        seq = simulate_cycab_run(gens[r], cfg.scene, cfg.cycab)
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        laser_w = np.array([_laser_world(p, seq.laser_pose) for p in truth])
        lm = seq.truth_landmarks
        feats: dict[str, list] = {}
        for m in sorted({v[1] for v in variants if r < runs_of[v[0]]}):
            t0 = time.perf_counter()
            params = extractor_params(m, cfg.cycab)
            feats[m] = [extract_features(seq.scan(k), m, **params) for k in range(seq.n_scans)]
            res.time_extract[m][r] = (time.perf_counter() - t0) / seq.n_scans
        noise_rng = gens[r].spawn(1)[0]
        for name, m, overrides, kind in variants:
            if r >= runs_of[name]:
                continue
            scfg = replace(cfg.slam, **overrides)
            fs = feats[m]
            if kind == "synthetic":
                fs = synthetic_features(
                    fs, seq, laser_w, scfg.noise_for(m)[1], noise_rng, cfg.false_match_m
                )
            elif kind == "debias":
                fs = [_push_out(f, -KASA_RANGE_BIAS_M) for f in fs]
            t0 = time.perf_counter()
            lg = slam_run(seq, features=fs, association=cfg.association, config=scfg)
            res.time_slam[name][r] = (time.perf_counter() - t0) / seq.n_scans
            e = lg.pose - truth
            e[:, 2] = wrap_angle(e[:, 2])
            # the paper's formula, over the scans after the first (which starts at the truth)
            res.abs_err[name][r] = np.mean(np.abs(e[1:]), axis=0)
            for k in range(1, seq.n_scans):
                res.nees[name][r, k] = float(e[k] @ np.linalg.solve(lg.pose_cov[k], e[k]))
            res.nis[name][r] = lg.scan_nis
            res.nis_dof[name][r] = lg.scan_nis_dof
            if name == m:
                for k, f in enumerate(feats[m]):
                    res.detected[name][r, k], res.false[name][r, k] = false_detections(
                        f, seq.scan_labels[k], laser_w[k], lm, cfg.false_match_m
                    )
            res.map_size[name][r] = lg.landmark_xy.shape[0]
            if lg.landmark_xy.shape[0]:
                d = np.hypot(
                    lg.landmark_xy[:, None, 0] - lm[None, :, 0],
                    lg.landmark_xy[:, None, 1] - lm[None, :, 1],
                )
                res.map_on_trees[name][r] = int(np.sum(d.min(axis=1) <= cfg.false_match_m))
            if r == 0 and name == m:
                res.logs0[m] = lg
        if r == 0:
            res.seq0 = seq
        if progress is not None:
            progress("table3/4 Monte Carlo", r + 1, R)
    res.seconds = time.perf_counter() - t_start
    return res


# ---- tables -------------------------------------------------------------------------------------


def nees_bounds(n_runs: int, dof: int = 3) -> tuple[float, float]:
    """95% bounds of the average NEES over n_runs runs (chi2_(n d) / n)."""
    lo, hi = chi2.ppf([0.025, 0.975], dof * n_runs) / n_runs
    return float(lo), float(hi)


def consistency(res: Exp2Results, name: str) -> dict:
    """NEES and NIS figures of one method or variant."""
    R = res.nees[name].shape[0]
    avg = np.nanmean(res.nees[name][:, 1:], axis=0)
    lo, hi = nees_bounds(R)
    nis_sum = np.nansum(np.where(res.nis_dof[name] > 0, res.nis[name], 0.0), axis=0)
    dof_sum = res.nis_dof[name].sum(axis=0)
    ok = dof_sum > 0
    nlo = chi2.ppf(0.025, dof_sum[ok])
    nhi = chi2.ppf(0.975, dof_sum[ok])
    inside_nis = (nis_sum[ok] >= nlo) & (nis_sum[ok] <= nhi)
    return {
        "nees_mean": float(np.mean(avg)),
        "nees_in": float(np.mean((avg >= lo) & (avg <= hi))),
        "nees_below": float(np.mean(avg < lo)),
        "nees_above": float(np.mean(avg > hi)),
        "nees_lo": lo,
        "nees_hi": hi,
        "nees_avg": avg,
        "nis_per_dof": float(nis_sum.sum() / dof_sum.sum()) if dof_sum.sum() else math.nan,
        "nis_in": float(np.mean(inside_nis)) if inside_nis.size else math.nan,
    }


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
    return out


def _write_tables(res: Exp2Results, out_dir: Path) -> list[Path]:
    cfg = res.config
    R = cfg.n_runs
    methods = cfg.methods
    paths: list[Path] = []
    # Table 3
    header = ["quantity", "unit"]
    for m in methods:
        header += [f"{m} mean", f"{m} std"]
    header += ["paper's proposed", "paper's Bailey"]
    rows = []
    for i, (q, unit) in enumerate((("dx", "m"), ("dy", "m"), ("dtheta", "rad"))):
        row: list = [q, unit]
        for m in methods:
            row += [
                round(float(res.abs_err[m][:, i].mean()), 4),
                round(float(res.abs_err[m][:, i].std(ddof=1)) if R > 1 else math.nan, 4),
            ]
        row += [PAPER_TABLE3["paper"][i], PAPER_TABLE3["bailey"][i]]
        rows.append(row)
    mean = {m: res.abs_err[m].mean(axis=0) for m in methods}
    notes = [
        (
            f"{R} Monte Carlo runs of {cfg.cycab.n_scans} scans (scene {cfg.scene}, association "
            f"{cfg.association}); per run the mean over the scans after the first of |dx|, |dy|, "
            "|dtheta| (the paper's formula, pose after each scan's update), then the mean and the "
            "standard deviation over the runs. The reference is the simulated EXACT pose, not the "
            "simulated 2 cm DGPS: scoring x, y against a 2 cm DGPS would add its own noise (mean "
            "|error| of 2 cm Gaussian noise: 0.016 m per axis), as large as the errors here. The "
            "paper's numbers are one real run against a real DGPS."
        ),
    ]
    if "paper" in mean and "bailey" in mean:
        lower = [bool(mean["paper"][i] < mean["bailey"][i]) for i in range(3)]
        notes.append(f"Direction as the paper (paper < bailey in dx, dy, dtheta): {lower}.")
    if "paper" in mean and "geometric" in mean:
        geo = [bool(mean["geometric"][i] <= mean["paper"][i]) for i in range(3)]
        notes.append(f"geometric <= paper in dx, dy, dtheta: {geo}.")
    paths += write_table(
        out_dir / "table3",
        header,
        rows,
        title="Table 3: average absolute pose error",
        notes="\n\n".join(notes),
    )
    # Table 4
    header = ["method"] + [f"scans {a}-{b}" for a, b in SCAN_SETS] + ["circles per scan"]
    rows = []
    for m in methods:
        rows.append(
            [f"{m} (ours)"]
            + [round(v, 4) for v in table4_rates(res, m)]
            + [round(float(res.detected[m].mean()), 2)]
        )
    rows.append(["proposed (paper)", *PAPER_TABLE4["paper"], "n/a"])
    rows.append(["Bailey (paper)", *PAPER_TABLE4["bailey"], "n/a"])
    notes4 = (
        f"The paper's rate: false features / detected features in a scan, averaged over the "
        f"scans of each set that have a detection (scan indices from 0, the sets inclusive) "
        f"and the {R} runs. A circle is false when the beams it was fitted to do not mostly hit "
        f"one trunk (per-beam truth labels: bushes, walls, mixed returns) or its centre lies more "
        f"than {cfg.false_match_m} m from that trunk's. The paper and geometric extractors find "
        "the same circles (they differ only in the fit), so their rates are equal."
    )
    paths += write_table(
        out_dir / "table4", header, rows, title="Table 4: false-detection rate", notes=notes4
    )
    # Consistency
    header = [
        "method",
        "runs",
        "NEES mean",
        "NEES in 95% bounds",
        "below",
        "above",
        "bounds",
        "NIS per dof",
        "NIS in 95% bounds",
        "landmarks",
        "on trees",
        "ms per scan",
    ]
    rows = []
    for name in res.nees:
        c = consistency(res, name)
        rows.append(
            [
                name,
                res.nees[name].shape[0],
                round(c["nees_mean"], 3),
                round(c["nees_in"], 3),
                round(c["nees_below"], 3),
                round(c["nees_above"], 3),
                f"[{c['nees_lo']:.2f}, {c['nees_hi']:.2f}]",
                round(c["nis_per_dof"], 3),
                round(c["nis_in"], 3),
                round(float(res.map_size[name].mean()), 2),
                round(float(res.map_on_trees[name].mean()), 2),
                round(1e3 * float(res.time_slam[name].mean()), 3),
            ]
        )
    notes_c = (
        "Vehicle-pose NEES (3 dof) averaged over the runs at each scan after the first; the "
        "fraction of scans where it lies inside its 95% chi-square bounds (target: at least "
        "0.9). NIS: per scan, the batch NIS summed over the runs against the chi-square bounds "
        "of the summed degrees of freedom; NIS per dof is the overall ratio (1 when "
        "consistent). Landmarks: final map size (mean over runs), and how many lie within "
        f"{cfg.false_match_m} m of a tree. ms per scan: the filter alone (prediction, "
        "association, update, map management), features extracted beforehand. Rows after the "
        "three methods are variants that explain the figures (see the README), on the first "
        f"{cfg.sensitivity_runs} runs."
    )
    paths += write_table(
        out_dir / "consistency",
        header,
        rows,
        title="Consistency of the EKF (NEES, NIS)",
        notes=notes_c,
    )
    return paths


# ---- figures and recording ----------------------------------------------------------------------


def _tree_of_landmarks(lg, lm: np.ndarray, tol: float) -> dict[int, int]:
    out = {}
    for lid, xy in zip(lg.landmark_id, lg.landmark_xy):
        d = np.hypot(*(lm[:, :2] - xy).T)
        if d.min() <= tol:
            out[int(lid)] = int(np.argmin(d))
    return out


def _write_figures(res: Exp2Results, out_dir: Path) -> list[Path]:
    from experiments import plots
    from experiments.sim import load_scene

    cfg = res.config
    seq = res.seq0
    scene = load_scene(cfg.scene)
    truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    paths = []
    main = "paper" if "paper" in res.logs0 else next(iter(res.logs0))
    lg = res.logs0[main]
    paths.append(
        plots.plot_slam_path(
            truth[:, :2],
            lg.pose[:, :2],
            seq.truth_landmarks,
            lg.landmark_xy,
            lg.landmark_cov,
            f"Fig. 7: true (dashed) and estimated path, {main} features, IHGR (run 0)",
            out_dir / "fig7_slam_path.png",
            walls=[w.points_xy for w in scene.walls],
            bushes=[b.points_xy for b in scene.bushes],
        )
    )
    pair = [m for m in ("paper", "bailey") if m in res.logs0] or list(res.logs0)
    # Fig. 10: innovations of the tree observed most often by both methods
    trees = {
        m: _tree_of_landmarks(res.logs0[m], seq.truth_landmarks, cfg.false_match_m) for m in pair
    }
    counts = {}
    for m in pair:
        lgm = res.logs0[m]
        for lid, j in trees[m].items():
            counts.setdefault(j, {})[m] = int(np.sum(lgm.obs_landmark == lid))
    best = max(counts, key=lambda j: min(counts[j].get(m, 0) for m in pair)) if counts else None
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
    paths.append(
        plots.plot_innovations(
            series,
            f"Fig. 10: innovations of tree {name} with 3 sigma bounds (run 0)",
            out_dir / "fig10_innovations.png",
        )
    )
    # Fig. 11: errors of the prediction with 3 sigma
    series = []
    for m in pair:
        lgm = res.logs0[m]
        e = lgm.pred_pose - truth
        e[:, 2] = wrap_angle(e[:, 2])
        sig = np.sqrt(np.maximum(np.diagonal(lgm.pred_pose_cov, axis1=1, axis2=2), 0.0))
        series.append(
            {
                "label": m,
                "scan": np.arange(seq.n_scans),
                "err": e,
                "sigma": sig,
                "style": STYLE.get(m, "-"),
            }
        )
    paths.append(
        plots.plot_pose_errors(
            series,
            "Fig. 11: predicted pose errors with 3 sigma bounds (run 0)",
            out_dir / "fig11_pose_errors.png",
        )
    )
    lo, hi = nees_bounds(cfg.n_runs)
    paths.append(
        plots.plot_consistency(
            {n: consistency(res, n)["nees_avg"] for n in cfg.methods},
            (lo, hi),
            f"Average vehicle-pose NEES over {cfg.n_runs} runs",
            "NEES (3 dof)",
            out_dir / "nees.png",
            expected=3.0,
        )
    )
    return paths


def _write_recording(res: Exp2Results, path: Path) -> Path:
    from experiments.viz import Recorder

    cfg = res.config
    seq = res.seq0
    rec = Recorder(path)
    rec.set_scan(0)
    rec.log_circles("world/truth/trees", seq.truth_landmarks, method="truth")
    m = "paper" if "paper" in cfg.methods else cfg.methods[0]
    params = extractor_params(m, cfg.cycab)
    slam_run(
        seq,
        features=m,
        feature_params=params,
        association=cfg.association,
        config=cfg.slam,
        visualiser=rec,
    )
    rec.close()
    return path


# ---- the registered experiment ------------------------------------------------------------------

_DONE: dict[tuple, tuple] = {}  # one run per reproduce call, shared by table3 and table4


def run_table34(ctx, cfg: Exp2Config | None = None) -> Exp2Results:
    """Experiment 2: Tables 3 and 4, Figs. 7, 10, 11, NEES/NIS and slam.rrd into ctx.out_dir."""
    key = (str(ctx.out_dir), ctx.seed, ctx.quick, id(ctx))
    if key in _DONE:
        res, resolved = _DONE[key]
        for name in ("table3", "table4"):
            if name in ctx.config and not ctx.config[name]:
                ctx.config[name] = resolved
        return res
    cfg = cfg or (Exp2Config.quick() if ctx.quick else Exp2Config())
    resolved = {
        "n_runs": cfg.n_runs,
        "methods": list(cfg.methods),
        "scene": cfg.scene,
        "association": cfg.association,
        "cycab": cfg.cycab.to_dict(),
        "slam": _plain(cfg.slam.to_dict()),
        "false_match_m": cfg.false_match_m,
        "extractor_params": {m: extractor_params(m, cfg.cycab) for m in cfg.methods},
        "sensitivity": [v[0] for v in SENSITIVITY] if cfg.sensitivity else [],
    }
    names = [n for n in ("table3", "table4") if n in ctx.config] or ["table3_4"]
    for name in names:
        ctx.config[name] = resolved
    res = monte_carlo(cfg, ctx.rng("slam"), progress=ctx.progress)
    out = Path(ctx.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = _write_tables(res, out) + _write_figures(res, out)
    written.append(_write_recording(res, out / "slam.rrd"))
    written.append(
        write_atomic(out / "slam_key_figures.json", dumps_json(_plain(key_figures(res))))
    )
    ctx.outputs += written
    log.info("experiment 2: %d runs in %.1f s", cfg.n_runs, res.seconds)
    _DONE.clear()
    _DONE[key] = (res, resolved)
    return res


def run_table3(ctx) -> None:
    """Registered as `table3` (computes both tables once per reproduce call)."""
    run_table34(ctx)


def run_table4(ctx) -> None:
    """Registered as `table4` (computes both tables once per reproduce call)."""
    run_table34(ctx)


def _plain(obj):
    """Dataclass dicts with tuples and numpy scalars as JSON types."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    return obj


# ---- `trunkslam slam` ---------------------------------------------------------------------------


def slam_command(
    input_path: Path | str,
    features: str = "paper",
    association: str = "ihgr",
    out_dir: Path | str = Path("slam_out"),
    rerun_path: Path | str | None = None,
    initial_heading: float | None = None,
    *,
    config: SlamConfig | None = None,
) -> dict:
    """`trunkslam slam INPUT.npz`: run EKF-SLAM and write the results into out_dir.

    trajectory.tum   the rear-axle centre at the scan times, `t x y z qx qy qz qw` (z = 0,
                     rotation about z by theta), readable by evo
    trajectory.csv   t, x, y, theta and the upper triangle of the pose covariance
    map.csv          id, x, y, covariance (xx, xy, yy), scan it joined the map, scans seen in
    summary.json     input, methods, start, counts, timings (mean, median, p95, max per phase),
                     the configuration, and when the sequence has truth the Table-3 errors and
                     the mean NEES
    Returns the summary. initial_heading: start heading in radians (GPS starts). config: the
    filter's settings (default `SlamConfig()`: the simulated Cycab's odometry noise and the
    calibrated measurement noise of the tree park).
    """
    from experiments.sequence import load_sequence
    from experiments.viz import open_recording

    seq = load_sequence(input_path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rec = open_recording(rerun_path)
    t0 = time.perf_counter()
    lg = slam_run(
        seq,
        features=features,
        association=association,
        config=config,
        visualiser=rec,
        initial_heading_rad=initial_heading,
    )
    seconds = time.perf_counter() - t0
    rec.close()
    th = lg.pose[:, 2]
    tum = "\n".join(
        f"{t:.6f} {x:.6f} {y:.6f} 0.0 0.0 0.0 {math.sin(a / 2):.9f} {math.cos(a / 2):.9f}"
        for t, x, y, a in zip(lg.scan_t, lg.pose[:, 0], lg.pose[:, 1], th)
    )
    write_atomic(out / "trajectory.tum", tum + "\n")
    lines = ["t_s,x_m,y_m,theta_rad,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta"]
    for t, p, C in zip(lg.scan_t, lg.pose, lg.pose_cov):
        lines.append(
            ",".join(
                f"{v:.9g}" for v in (t, *p, C[0, 0], C[0, 1], C[0, 2], C[1, 1], C[1, 2], C[2, 2])
            )
        )
    write_atomic(out / "trajectory.csv", "\n".join(lines) + "\n")
    lines = ["id,x_m,y_m,cov_xx,cov_xy,cov_yy,first_scan,n_obs"]
    for i, xy, C, f, n in zip(
        lg.landmark_id, lg.landmark_xy, lg.landmark_cov, lg.landmark_first_scan, lg.landmark_n_obs
    ):
        lines.append(
            f"{i},{xy[0]:.6f},{xy[1]:.6f},{C[0, 0]:.9g},{C[0, 1]:.9g},{C[1, 1]:.9g},{f},{n}"
        )
    write_atomic(out / "map.csv", "\n".join(lines) + "\n")
    timing = {}
    for k, v in lg.timing_s.items():
        timing[k] = {
            "mean_ms": 1e3 * float(np.mean(v)),
            "median_ms": 1e3 * float(np.median(v)),
            "p95_ms": 1e3 * float(np.percentile(v, 95)),
            "max_ms": 1e3 * float(np.max(v)),
            "total_s": float(np.sum(v)),
        }
    summary = {
        "input": str(input_path),
        "features": lg.features_method,
        "association": lg.association_method,
        "n_scans": lg.n_scans,
        "start": lg.start,
        "landmarks": int(lg.landmark_xy.shape[0]),
        "circles_per_scan": float(lg.n_features.mean()),
        "associated_per_scan": float(lg.n_associated.mean()),
        "seconds": seconds,
        "timing": timing,
        "config": _plain(lg.config),
    }
    inside = (
        np.zeros(seq.n_scans, bool)
        if seq.truth_t is None
        else (seq.scan_t >= seq.truth_t[0]) & (seq.scan_t <= seq.truth_t[-1])
    )
    inside[0] = False  # the run may start at the truth
    if inside.any():  # score only the scans the truth covers
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        e = (lg.pose - truth)[inside]
        e[:, 2] = wrap_angle(e[:, 2])
        covs = lg.pose_cov[inside]
        nees = [
            float(ek @ np.linalg.solve(ck, ek)) for ek, ck in zip(e, covs) if np.linalg.det(ck) > 0
        ]
        summary["truth"] = {
            "mean_abs_error": dict(
                zip(("dx_m", "dy_m", "dtheta_rad"), np.mean(np.abs(e), 0).tolist())
            ),
            "nees_mean": float(np.mean(nees)) if nees else None,
            "scans_scored": int(inside.sum()),
        }
    write_atomic(out / "summary.json", dumps_json(summary))
    return summary


# ---- calibration of the constant measurement noise ----------------------------------------------


def calibrate_measurement_noise(
    seeds=(1000, 1001, 1002, 1003), cycab: CycabParams | None = None, scene: str = "tree_park"
) -> dict:
    """Fit the constant noise model of `slam.run.DEFAULT_CONSTANT_NOISE` to the extractors' centre
    errors on circles found on trunks (majority of beams on one trunk), by maximum likelihood of
    zero-mean Gaussian errors: range error ~ N(0, (a + b r)^2), bearing error ~ N(0, c^2 +
    (t / r)^2) (a bias is absorbed into the spread). Returns method -> dict of the fitted
    values, the RMS errors and the normalised error variances under the fit (1 = calibrated)."""
    from scipy.optimize import minimize

    cycab = cycab or CycabParams()
    errs: dict[str, list] = {m: [] for m in METHODS}
    for seed in seeds:
        seq = simulate_cycab_run(np.random.default_rng(seed), scene, cycab)
        truth = interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        lm = seq.truth_landmarks
        for k in range(seq.n_scans):
            lw = _laser_world(truth[k], seq.laser_pose)
            d = lm[:, :2] - lw[:2]
            tr = np.hypot(*d.T)
            tb = np.arctan2(d[:, 1], d[:, 0]) - lw[2]
            for m in METHODS:
                f = extract_features(seq.scan(k), m, **extractor_params(m, cycab))
                for (a, b), p in zip(f.circle_beams, f.circle_params):
                    lab = seq.scan_labels[k][a : b + 1]
                    lab = lab[lab >= 0]
                    if lab.size == 0 or np.bincount(lab).argmax() >= lm.shape[0]:
                        continue
                    j = int(np.bincount(lab).argmax())
                    r = math.hypot(p[0], p[1])
                    eb = float(wrap_angle(math.atan2(p[1], p[0]) - tb[j]))
                    errs[m].append((tr[j], r - tr[j], eb))
    out = {}
    for m, v in errs.items():
        v = np.array(v)
        r, er, eb = v[:, 0], v[:, 1], v[:, 2]

        def nll_range(q, r=r, er=er):
            s = np.abs(q[0]) + np.abs(q[1]) * r
            return float(np.sum(np.log(s) + 0.5 * (er / s) ** 2))

        def nll_bearing(q, r=r, eb=eb):
            s2 = q[0] ** 2 + (q[1] / r) ** 2
            return float(np.sum(0.5 * np.log(s2) + 0.5 * eb**2 / s2))

        qa = np.abs(
            minimize(
                nll_range,
                [0.01, 0.001],
                method="Nelder-Mead",
                options={"xatol": 1e-7, "fatol": 1e-6, "maxiter": 4000},
            ).x
        )
        qb = np.abs(
            minimize(
                nll_bearing,
                [0.001, 0.005],
                method="Nelder-Mead",
                options={"xatol": 1e-8, "fatol": 1e-6, "maxiter": 4000},
            ).x
        )
        sr = qa[0] + qa[1] * r
        sb2 = qb[0] ** 2 + (qb[1] / r) ** 2
        out[m] = {
            "n": len(v),
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


def main(argv=None) -> None:  # pragma: no cover - a script
    ap = argparse.ArgumentParser(description="experiment 2 helpers")
    ap.add_argument(
        "--write-golden",
        action="store_true",
        help=f"run the quick experiment (seed 0) and write {GOLDEN_PATH}",
    )
    ap.add_argument(
        "--calibrate",
        action="store_true",
        help="fit the constant measurement-noise model (seeds 1000-1003)",
    )
    args = ap.parse_args(argv)
    if args.write_golden:
        res = monte_carlo(Exp2Config.quick(), golden_rng())
        figs = key_figures(res)
        figs["_note"] = (
            "written by `python -m experiments.exp_slam --write-golden`: "
            "Exp2Config.quick(), golden_rng(); compared by tests/test_slam_experiment.py"
        )
        GOLDEN_PATH.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(GOLDEN_PATH, json.dumps(figs, indent=1, sort_keys=True) + "\n")
        print(json.dumps(figs, indent=1))
    if args.calibrate:
        print(json.dumps(calibrate_measurement_noise(), indent=1))


def golden_rng() -> np.random.Generator:
    """The generator of the golden quick run (what `RunContext(seed=0).rng("slam")` gives)."""
    return np.random.default_rng(np.random.SeedSequence([0] + [ord(c) for c in "slam"]))


if __name__ == "__main__":  # pragma: no cover
    main()

"""`trunkslam sweep CONFIG.toml`: a study run over a grid (or a list) of configuration values.

The sweep file (TOML; examples in datasets/sweeps/sweep_*.toml):

    study = "slam"            # association, slam or circles (`STUDIES`)
    trials = 20               # trials per point
    seed = 0                  # root seed
    [base]                    # fields held fixed at every point (dotted names or tables)
    "cycab.n_scans" = 120
    [grid]                    # every combination of these values ...
    "cycab.range_sigma_m" = [0.01, 0.03, 0.05]
    # ... or a list of points instead:  [[points]]  "cycab.range_sigma_m" = 0.01
    [executor]                # optional: where the trials run (--workers / --dask win)
    workers = 2               # or dask = "tcp://host:8786"

A field is a dotted path into the study's configuration (`trunkslam sweep --fields STUDY`
prints them with their defaults); a wrong name, type or value is an error naming it. Every
(point, trial) is one trial on the executor; trial q has the same seed at every point (common
random numbers: points differ by the swept value, not by the luck of the draw). Writes, into
one output folder (replaced as a set): sweep.csv (tidy: one row per point, method and metric,
with the mean, standard deviation and number of trials), sweep_<field>.png per swept field,
and sweep.json (the file's settings, every point resolved, the executor, failed trials with
their seeds) last.
"""

from __future__ import annotations

import csv
import functools
import io
import itertools
import logging
import math
import time
import tomllib
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError, DataError, ExperimentFailed
from experiments.exec import Executor, TrialsFailed, make_executor, spawn_seeds
from experiments.io.outputs import check_output_folder, check_outputs, lock_folder, write_manifest
from experiments.io.paths import check_depth, read_text_file
from experiments.io.writers import atomic_folder, dumps_json, json_types, write_atomic
from experiments.paper.runner import experiment_seed

__all__ = ["STUDIES", "Study", "load_sweep", "run_sweep_file", "study_defaults"]

log = logging.getLogger(__name__)

SUMMARY = "sweep.json"


# ---- the studies --------------------------------------------------------------------------------


def _association_config(point: dict):
    from experiments.sim.landmarks import LandmarkSimConfig
    from slam.config import config_from_dict

    gate = _number(point, "gate_prob")
    if not 0.0 < gate < 1.0:
        raise ConfigError(f"gate_prob: must be in (0, 1), got {gate!r}")
    return config_from_dict(LandmarkSimConfig, point["sim"], "sim"), gate


def _number(point: dict, key: str) -> float:
    """point[key], a finite real number (not a string, a boolean or a huge integer)."""
    v = point[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not abs(v) < 1e300:
        raise ConfigError(f"{key}: expected a finite number, got {_shown(v)}")
    if math.isnan(v):
        raise ConfigError(f"{key}: expected a finite number, got nan")
    return float(v)


def _shown(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _methods(point: dict, allowed) -> tuple[str, ...]:
    m = point["methods"]
    if (
        not isinstance(m, list)
        or not m
        or any(not isinstance(x, str) or x not in allowed for x in m)
    ):
        raise ConfigError(f"methods: expected some of {', '.join(allowed)}, got {_shown(m)}")
    return tuple(m)


def association_trial(point: dict, seed) -> dict:
    """One simulated sequence: per method, its correct, false-pairing and missed-pairing rates
    and ms per scored scan (experiment `association`'s measures)."""
    from experiments.paper.association import EVAL_FROM_SCAN, run_methods
    from experiments.sim.landmarks import simulate_landmark_scans

    cfg, gate = _association_config(point)
    st = run_methods(simulate_landmark_scans(cfg, np.random.default_rng(seed)), cfg, gate_prob=gate)
    out = {}
    for m, s in st.items():
        n = max(s["n"], 1)
        out[m] = {
            "correct_rate": s["correct"] / n,
            "false_pair_rate": s["false_pair"] / n,
            "missed_pair_rate": s["missed_pair"] / n,
            "ms_per_scan": 1e3 * s["seconds"] / max(cfg.n_scans - EVAL_FROM_SCAN, 1),
        }
    return out


def _slam_config(point: dict):
    """Experiment 2's configuration of a point, with everything its trial builds before it runs
    checked: the scene and its route, the car and its sensor, each method's filter settings."""
    from experiments.paper.slam import Exp2Config, run_config
    from experiments.sim.trajectory import CycabParams
    from slam import SlamConfig
    from slam.config import ASSOCIATION_METHODS, config_from_dict

    methods = _methods(point, ("paper", "geometric", "bailey"))
    for key in ("scene", "association"):
        if not isinstance(point[key], str):
            raise ConfigError(f"{key}: expected a string, got {_shown(point[key])}")
    if point["association"] not in ASSOCIATION_METHODS:
        raise ConfigError(
            f"association: expected one of {', '.join(ASSOCIATION_METHODS)}, got "
            f"{_shown(point['association'])}"
        )
    false_match = _number(point, "false_match_m")
    if not false_match > 0:
        raise ConfigError(f"false_match_m: must be > 0, got {false_match!r}")
    _route(point["scene"])
    cfg = Exp2Config(
        n_runs=1,
        methods=methods,
        scene=point["scene"],
        cycab=config_from_dict(CycabParams, point["cycab"], "cycab"),
        association=point["association"],
        slam=config_from_dict(SlamConfig, point["slam"], "slam"),
        false_match_m=false_match,
        sensitivity=False,
        smoother=False,
    )
    for m in methods:  # the filter of each method: its extractor and the association
        try:
            run_config(cfg, m)
        except ValueError as exc:
            raise ConfigError(f"slam (with features.method = {m!r}): {exc}") from None
    return cfg


@functools.cache
def _route(scene: str) -> None:
    """The scene exists and has a route to drive (its scan positions); once per scene."""
    from experiments.sim.scene import load_scene

    try:
        sc = load_scene(scene)
    except ValueError as exc:
        raise ConfigError(f"scene: {exc}") from None
    if sc.scan_positions.shape[0] < 2:
        raise ConfigError(f"scene: {scene!r} has no route (fewer than 2 scan_positions)")


def slam_trial(point: dict, seed) -> dict:
    """One simulated Cycab run (experiment 2's `slam_trial`): per method, the mean |dx|, |dy|,
    |dtheta| (Table 3's formula), mean NEES, NIS per dof, final landmarks and the share of false
    circles (Table 4's, over all scans)."""
    from experiments.paper.slam import slam_trial as exp2_trial

    rec = exp2_trial((_slam_config(point), 0, False), seed)
    out = {}
    for m, o in rec["runs"].items():
        dof = o["nis_dof"].sum()
        det = o["detected"].sum()
        out[m] = {
            "dx_m": float(o["abs_err"][0]),
            "dy_m": float(o["abs_err"][1]),
            "dtheta_rad": float(o["abs_err"][2]),
            "nees_mean": float(np.nanmean(o["nees"])),
            "nis_per_dof": float(np.nansum(o["nis"]) / dof) if dof else math.nan,
            "landmarks": float(o["map_size"]),
            "false_rate": float(o["false"].sum() / det) if det else math.nan,
        }
    return out


def _circles_config(point: dict) -> tuple[tuple, dict]:
    from experiments.paper.circles import METHODS
    from experiments.sim.simulate import sensor_preset

    methods = _methods(point, METHODS)
    kw = {k: _number(point, k) for k in ("range_m", "radius_m", "noise_m")}
    if not all(0 < v < 1e6 for v in kw.values()):
        raise ConfigError(f"range_m, radius_m and noise_m must be positive, got {kw}")
    if kw["radius_m"] >= kw["range_m"]:
        raise ConfigError(f"radius_m: {kw['radius_m']:g} m, the pillar would hold the laser")
    sensor_preset("pls200", range_sigma_m=kw["noise_m"])  # the sensor the trial simulates
    return methods, kw


def circles_trial(point: dict, seed) -> dict:
    """One scan of one pillar straight ahead (the circle sweep's set-up): per method, its CE
    and RE (eq. 10, 11; NaN when not extracted) and whether it was extracted; and the
    Cramer-Rao bound's (as 'crlb', RMS)."""
    from experiments.paper.circles import sweep_point

    methods, kw = _circles_config(point)
    res = sweep_point(np.random.default_rng(seed), n_trials=1, methods=methods, **kw)
    return {m: {"ce": ce, "re": re, "extracted": frac} for m, (ce, re, frac) in res.items()}


@dataclass(frozen=True)
class Study:
    """A sweepable study: its default configuration (a plain nested dict), what checks a point
    (raises ConfigError/SlamError naming the field) and its trial."""

    about: str
    defaults: Callable[[], dict]
    check: Callable[[dict], object]
    trial: Callable[[dict, object], dict]


def _association_defaults() -> dict:
    from experiments.sim.landmarks import LandmarkSimConfig

    return {"sim": asdict(LandmarkSimConfig()), "gate_prob": 0.99}


def _slam_defaults() -> dict:
    from experiments.paper.slam import METHODS, Exp2Config

    cfg = Exp2Config()
    return {
        "methods": list(METHODS),
        "scene": cfg.scene,
        "association": cfg.association,
        "cycab": cfg.cycab.to_dict(),
        "slam": cfg.slam.to_dict(),
        "false_match_m": cfg.false_match_m,
    }


def _circles_defaults() -> dict:
    from experiments.paper.circles import METHODS, SWEEP_DEFAULT

    return {"methods": list(METHODS), **SWEEP_DEFAULT}


STUDIES = {
    "association": Study(
        "IHGR, JCBB and NN on simulated landmark maps (experiment association): sim.* are "
        "the simulator's fields, gate_prob the gates' chi-square probability",
        _association_defaults,
        _association_config,
        association_trial,
    ),
    "slam": Study(
        "EKF-SLAM on the simulated tree park (experiment 2, Tables 3-4): cycab.* the car, "
        "sensors and odometry noise, slam.* the filter (slam.association.gate_prob, ...), "
        "association",
        _slam_defaults,
        _slam_config,
        slam_trial,
    ),
    "circles": Study(
        "one pillar ahead of a PLS200 (the circle sweep): range_m, radius_m, noise_m, methods",
        _circles_defaults,
        _circles_config,
        circles_trial,
    ),
}


def study_defaults(name: str) -> dict:
    """The study's configuration at its defaults, as dotted names -> values."""
    return _flatten(_study(name).defaults())


def fields_toml(name: str) -> str:
    """The study's fields at their defaults as the [base] table of a sweep file (valid TOML,
    one dotted name per line): what `trunkslam sweep --fields` prints."""
    import tomli_w

    fields = study_defaults(name)
    unset = [k for k, v in fields.items() if v is None]  # TOML has no null: left as comments
    head = f"# {name}: {_study(name).about}\n"
    head += "".join(f"# {k}: not set by default (the study chooses; settable)\n" for k in unset)
    given = {k: v for k, v in fields.items() if v is not None}
    return head + f"study = {name!r}\n\n" + tomli_w.dumps({"base": given})


def _study(name) -> Study:
    if name not in STUDIES:
        raise ConfigError(f"study: unknown study {name!r}; known: {', '.join(STUDIES)}")
    return STUDIES[name]


# ---- the sweep file -----------------------------------------------------------------------------


def _flatten(d: dict, prefix: str = "") -> dict:
    """Nested tables as dotted names; a value that is not a table is a leaf."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _set(config: dict, dotted: str, value, where: str) -> None:
    """config[a][b][c] = value for "a.b.c"; the path must exist in the defaults, and the value
    be of the default's kind (a number for a number, a list for a list, ...)."""
    *parents, leaf = dotted.split(".")
    node = config
    for i, p in enumerate(parents):
        if not isinstance(node.get(p), dict):
            raise ConfigError(f"{where}: {dotted!r} is not a field ({'.'.join(parents[: i + 1])})")
        node = node[p]
    if leaf not in node:
        known = ", ".join(sorted(node))
        raise ConfigError(f"{where}: {dotted!r} is not a field (known here: {known})")
    _check_kind(node[leaf], value, f"{where}: {dotted}")
    node[leaf] = value


def _check_kind(default, value, where: str) -> None:
    """`value` of the kind of the field's default (its own checks come with the study's)."""
    if default is None:
        ok = isinstance(value, (int, float, str, list)) and not isinstance(value, bool)
        want = "a value"
    elif isinstance(default, bool):
        ok, want = isinstance(value, bool), "true or false"
    elif isinstance(default, (int, float)):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        want = "a number"
    elif isinstance(default, str):
        ok, want = isinstance(value, str), "a string"
    elif isinstance(default, (list, tuple)):
        ok, want = isinstance(value, list), "a list"
    else:  # a table
        ok, want = isinstance(value, dict), "a table"
    if not ok:
        raise ConfigError(f"{where}: expected {want}, got {_shown(value)}")


# The most trials (points x trials) a sweep file may ask for: at the slam study's 2-3 s a trial
# on one core, 100,000 trials are about 3 days on a 2-core machine.
MAX_SWEEP_TRIALS = 100_000
_TOP = {"study", "trials", "seed", "base", "grid", "points", "executor"}


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep file: the study, trials per point, root seed, the resolved configuration
    of every point (plain nested dicts), the swept fields and each point's values of them, and
    the [executor] table."""

    study: str
    trials: int
    seed: int
    points: list
    swept: list
    values: list
    executor: dict
    source: dict


def load_sweep(path: Path | str) -> SweepSpec:
    """Read and check a sweep file: its structure, then every point's resolved configuration
    as its trials will build it (scene, car, sensor, filter), before any trial runs. Errors
    (`ConfigError`) name the file, the key and the point."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise ConfigError(f"{path}: no such sweep file")
    try:
        data = tomllib.loads(read_text_file(path, "sweep file"))
        check_depth(data, path)
    except DataError as exc:
        raise ConfigError(str(exc)) from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply to be a sweep file") from None
    try:
        return _parse_sweep(data, path)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def _parse_sweep(data: dict, path: Path) -> SweepSpec:
    """The checked `SweepSpec` of a parsed sweep file (errors without the file's name)."""
    extra = sorted(set(data) - _TOP)
    if extra:
        raise ConfigError(f"{extra[0]}: unknown key (known: {', '.join(sorted(_TOP))})")
    if "study" not in data:
        raise ConfigError(f"study: missing (one of {', '.join(STUDIES)})")
    if not isinstance(data["study"], str):
        raise ConfigError(f"study: expected a string, got {_shown(data['study'])}")
    study = _study(data["study"])
    trials, seed = data.get("trials", 10), data.get("seed", 0)
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ConfigError(f"trials must be a whole number >= 1, got {_shown(trials)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError(f"seed must be a whole number >= 0, got {_shown(seed)}")
    for key in ("base", "grid", "executor"):
        if key in data and not isinstance(data[key], dict):
            raise ConfigError(f"{key}: expected a table, got {_shown(data[key])}")
    if ("grid" in data) == ("points" in data):
        which = "both" if "grid" in data else "neither"
        raise ConfigError(f"give either [grid] or [[points]], not {which}")
    swept, values, where = _points(data)
    n = len(values) * trials
    if n > MAX_SWEEP_TRIALS:
        raise ConfigError(
            f"trials: {len(values)} points x {trials} trials = {n} trials, more than the "
            f"limit of {MAX_SWEEP_TRIALS} (experiments.paper.sweep.MAX_SWEEP_TRIALS)"
        )
    executor = _executor(data.get("executor", {}))
    base = study.defaults()
    for k, v in _flatten(data.get("base", {})).items():
        _set(base, k, v, "base")
    points = []
    for j, vals in enumerate(values):
        point = _copy(base)
        for k, v in zip(swept, vals):
            _set(point, k, v, where(j))
        try:
            study.check(point)
        except (TypeError, ValueError) as exc:  # ConfigError, SlamError, DataError: the point
            shown = ", ".join(f"{k} = {_shown(v)}" for k, v in zip(swept, vals))
            raise ConfigError(f"point {j} ({shown}): {exc}") from None
        points.append(point)
    return SweepSpec(
        study=data["study"],
        trials=trials,
        seed=seed,
        points=points,
        swept=swept,
        values=values,
        executor=executor,
        source=data,
    )


def _points(data: dict):
    """(swept fields, each point's values of them, where(j): the key of point j)."""
    if "grid" in data:
        grid = _flatten(data["grid"])
        if not grid:
            raise ConfigError("grid: empty; give at least one field with its values")
        for k, v in grid.items():
            if not isinstance(v, list) or not v:
                raise ConfigError(f"grid.{k} must be a non-empty list of values")
        values = [list(c) for c in itertools.product(*grid.values())]
        if len(values) > MAX_SWEEP_TRIALS:
            raise ConfigError(f"grid: {len(values)} points, more than {MAX_SWEEP_TRIALS}")
        return list(grid), values, lambda j: "grid"
    raw = data["points"]
    if not isinstance(raw, list) or not raw or not all(isinstance(p, dict) for p in raw):
        raise ConfigError("points: expected a non-empty list of tables ([[points]])")
    pts = [_flatten(p) for p in raw]
    swept = list(dict.fromkeys(k for p in pts for k in p))
    if not swept:
        raise ConfigError("points: every point is empty; give each the fields it sets")
    for j, p in enumerate(pts):
        if set(p) != set(swept):
            raise ConfigError(f"points[{j}] sets {sorted(p)}, the others {swept}")
    return swept, [[p[k] for k in swept] for p in pts], lambda j: f"points[{j}]"


def _executor(ex: dict) -> dict:
    """The [executor] table: workers (a whole number >= 1) or dask (a scheduler address)."""
    if set(ex) - {"workers", "dask"}:
        raise ConfigError(f"executor: takes workers and dask, got {sorted(ex)}")
    w = ex.get("workers")
    if w is not None and (isinstance(w, bool) or not isinstance(w, int) or not 1 <= w <= 4096):
        raise ConfigError(f"executor.workers: must be a whole number in 1..4096, got {_shown(w)}")
    d = ex.get("dask")
    if d is not None and (not isinstance(d, str) or not d.strip()):
        raise ConfigError(f"executor.dask: expected a scheduler address, got {_shown(d)}")
    return ex


def _copy(d):
    return {k: _copy(v) for k, v in d.items()} if isinstance(d, dict) else d


# ---- running it ---------------------------------------------------------------------------------


def sweep_rows(spec: SweepSpec, records: list) -> list[list]:
    """Tidy rows [point, *swept values, method, metric, mean, std, n] from the records of every
    (point, trial) in order (None for a failed trial)."""
    rows = []
    T = spec.trials
    for j, vals in enumerate(spec.values):
        got = [r for r in records[j * T : (j + 1) * T] if r is not None]
        methods = list(dict.fromkeys(m for r in got for m in r))
        for m in methods:
            metrics = list(dict.fromkeys(k for r in got for k in r.get(m, {})))
            for k in metrics:
                v = np.array([r[m][k] for r in got if m in r], float)
                ok = v[np.isfinite(v)]
                mean = float(ok.mean()) if ok.size else math.nan
                std = float(ok.std(ddof=1)) if ok.size > 1 else math.nan
                rows.append([j, *vals, m, k, mean, std, int(ok.size)])
    return rows


# the figures' words for the studies and their trials' metrics: (panel title, y label and unit)
STUDY_TITLES = {
    "association": "Data association on simulated maps",
    "slam": "EKF-SLAM on the simulated tree park",
    "circles": "One pillar ahead of a PLS200",
}
METRICS = {
    "correct_rate": ("correct associations", "share of the measurements"),
    "false_pair_rate": ("false pairings", "share of the measurements"),
    "missed_pair_rate": ("missed pairings", "share of the measurements"),
    "ms_per_scan": ("association time", "time (ms per scan)"),
    "dx_m": ("mean |x error| of the vehicle", "|x error| (m)"),
    "dy_m": ("mean |y error| of the vehicle", "|y error| (m)"),
    "dtheta_rad": ("mean |heading error| of the vehicle", "|heading error| (rad)"),
    "nees_mean": ("vehicle-pose NEES, mean over the scans", "NEES (3 dof, no unit)"),
    "nis_per_dof": ("NIS per degree of freedom", "NIS / dof (no unit)"),
    "landmarks": ("landmarks in the final map", "landmarks (count)"),
    "false_rate": ("false circles (Table 4)", "share of the detected features"),
    "ce": ("centre error CE (eq. 10)", "centre error / range (no unit)"),
    "re": ("radius error RE (eq. 11)", "radius error / radius (no unit)"),
    "extracted": ("pillar extracted as a circle", "share of the trials"),
}


def _references(spec: SweepSpec) -> dict[str, list[tuple]]:
    """What a consistent filter gives, drawn on the slam study's panels: the mean NEES's 95%
    band and expected value 3, the NIS per dof's expected value 1.

    The band is the 95% chi-square bounds of one scan's NEES averaged over the point's trials,
    chi2_(3n)(0.025, 0.975) / n (`nees_bounds`, as nees.png): a wide band for the NEES averaged
    over the scans of each trial too, whose spread is smaller. The NIS per dof's own bounds
    depend on the degrees of freedom summed over a run, which sweep.csv does not keep."""
    from experiments.eval.poses import nees_bounds

    if spec.study != "slam":
        return {}
    band = nees_bounds(spec.trials)
    return {
        "nees_mean": [
            ("band", band, f"95% NEES bounds over {spec.trials} runs (chi2, 3 dof)"),
            ("line", 3.0, "expected value of a consistent filter (NEES 3, NIS per dof 1)"),
        ],
        "nis_per_dof": [
            ("line", 1.0, "expected value of a consistent filter (NEES 3, NIS per dof 1)")
        ],
    }


def run_sweep(
    spec: SweepSpec, out_dir: Path, executor: Executor, progress=None
) -> tuple[list[Path], list]:
    """Run a parsed sweep into out_dir (replaced as one set); returns (files written, failed
    trials). Failed trials are left out of the means (column n) and listed in sweep.json."""
    from experiments.paper import sweep_figures

    out_dir = Path(out_dir)
    check_output_folder(out_dir, "--out", "sweep")
    study = _study(spec.study)
    seeds = spawn_seeds(experiment_seed(spec.seed, f"sweep:{spec.study}"), spec.trials)
    jobs = [p for p in spec.points for _ in range(spec.trials)]
    t0 = time.perf_counter()
    failures = []
    try:
        records = executor.map(
            study.trial, jobs, seeds * len(spec.points), desc="sweep", progress=progress
        )
    except TrialsFailed as exc:
        records, failures = exc.records, exc.failures
    seconds = time.perf_counter() - t0
    rows = sweep_rows(spec, records)
    header = ["point", *spec.swept, "method", "metric", "mean", "std", "n"]
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    with atomic_folder(out_dir) as stage:
        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(header)
        w.writerows(rows)
        written = [write_atomic(stage / "sweep.csv", buf.getvalue())]
        for k, field in enumerate(spec.swept):
            name = f"sweep_{field}.png"
            title = f"{STUDY_TITLES[spec.study]}: {spec.trials} trials per point, {field} swept"
            written.append(
                sweep_figures.plot_sweep_field(
                    rows,
                    spec.swept,
                    k,
                    title,
                    stage / name,
                    metrics=METRICS,
                    references=_references(spec),
                )
            )
        summary = {
            "study": spec.study,
            "trials": spec.trials,
            "seed": spec.seed,
            "file": spec.source,
            "swept": spec.swept,
            "points": [{"values": v, "config": p} for v, p in zip(spec.values, spec.points)],
            "executor": executor.describe(),
            "seconds": round(seconds, 2),
            "failed": [
                {"point": f.index // spec.trials, "trial": f.index % spec.trials, **asdict(f)}
                for f in failures
            ],
        }
        written.append(write_atomic(stage / SUMMARY, dumps_json(json_types(summary))))
        write_manifest(stage, "sweep")  # last: the set is complete
    return [out_dir / p.name for p in written], failures


def run_sweep_file(
    path: Path | str,
    out_dir: Path,
    workers: int | None = None,
    dask: str | None = None,
    progress=None,
) -> list[Path]:
    """`trunkslam sweep`: read the file, run it on --workers / --dask (else its [executor],
    else every local core), write the set. Raises ExperimentFailed (after writing) when trials
    failed, naming them with their seeds."""
    check_outputs("sweep", inputs=[path], folders={"--out": out_dir})
    spec = load_sweep(path)
    if workers is None and dask is None:
        workers, dask = spec.executor.get("workers"), spec.executor.get("dask")
    with lock_folder(out_dir, "--out"), make_executor(workers, dask) as executor:
        written, failures = run_sweep(spec, out_dir, executor, progress)
    if failures:
        shown = "; ".join(str(f) for f in failures[:3])
        raise ExperimentFailed(
            f"{len(failures)} trial(s) of the sweep failed ({shown}); the others are in "
            f"{out_dir}/ ({SUMMARY} lists every failure with its seed)"
        )
    return written

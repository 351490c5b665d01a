"""Experiment `association`: IHGR (single scan and K-scan window), JCBB and NN side by side.

Writes
  association.md / .csv      correct-association rate on simulated maps with known truth, for
                             increasing clutter, landmark density and pose uncertainty; then the
                             section "In the SLAM loop" (`experiments.paper.association_loop`)
  association_loop.csv       that section's table: every method running the whole EKF-SLAM
                             loop in the tree park (odometry noise x1, x2, x4) and on the full
                             Victoria Park run (published detections; skipped without the data)
  association.png            the same as curves
  association_optimality.md  IHGR against the exact integer optimum (scipy.optimize.milp) on
                             random single-scan and multi-scan instances (summary)
  association_optimality.csv the same, one row per instance and IHGR variant

The simulated worlds come from `experiments.sim.landmarks.simulate_landmark_scans` (point
landmarks, a short drive, consistent EKF-like predictions, noise, misses and clutter).
"""

from __future__ import annotations

import csv
import io
import logging
import math
import time
from dataclasses import asdict, dataclass, replace

import numpy as np

from association import CostModel, SlidingWindowAssociator, associate_detailed, solve_set_partition
from association.inputs import prepare
from association.single import single_scan_problem
from experiments.exec import SerialExecutor
from experiments.io.writers import markdown_table, write_atomic
from experiments.paper import association_figures, products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.sim.landmarks import LandmarkScan, LandmarkSimConfig, simulate_landmark_scans

log = logging.getLogger(__name__)

__all__ = [
    "RATE_TABLE",
    "RateStudy",
    "cost_model_for",
    "instances_trial",
    "optimality_instances",
    "optimality_study",
    "optimality_trial",
    "rate_study",
    "rate_trial",
    "run",
]

METHOD_LABELS = {
    "ihgr": "IHGR (single scan)",
    "ihgr_k3": "IHGR (K = 3 window)",
    "jcbb": "JCBB",
    "nn": "NN",
}


def cost_model_for(cfg: LandmarkSimConfig) -> CostModel:
    """IHGR's densities set to the simulator's rates (measurement space: max range x 2 pi)."""
    vol = cfg.max_range_m * 2 * np.pi
    unmapped_per_scan = (
        cfg.density_per_100m2
        / 100.0
        * np.pi
        * cfg.max_range_m**2
        * cfg.unmapped_fraction
        * cfg.p_detect
    )
    return CostModel(
        p_detect=cfg.p_detect,
        clutter_density=max(cfg.clutter_per_scan, 0.01) / vol,
        birth_density=max(unmapped_per_scan, 0.01) / vol,
    )


# --------------------------------------------------------------------------------------------
# Correct-association rate
# --------------------------------------------------------------------------------------------

# The association study's gate probability: this study's own setting since its first tables (the
# SLAM loop's is `slam.config.AssociationConfig.gate_prob`, 0.999; `association` has no default).
STUDY_GATE_PROB = 0.99
EVAL_FROM_SCAN = 2  # scans before this only warm up the window (K = 3) and are not scored


def run_methods(
    seq: list[LandmarkScan],
    cfg: LandmarkSimConfig,
    methods=tuple(METHOD_LABELS),
    gate_prob: float = STUDY_GATE_PROB,
    max_nodes: int = 20_000,
) -> dict:
    """Counts per method over the scored scans of one sequence."""
    model = cost_model_for(cfg)
    win = SlidingWindowAssociator(K=3, gate_prob=gate_prob, model=model)
    stats = {
        m: {
            "n": 0,
            "correct": 0,
            "false_pair": 0,
            "missed_pair": 0,
            "seconds": 0.0,
            "budget_hits": 0,
            "unmapped": 0,
            "unmapped_confirmed": 0,
            "clutter": 0,
            "clutter_confirmed": 0,
        }
        for m in methods
    }
    cm = asdict(model)
    for t, s in enumerate(seq):
        for m in methods:
            t0 = time.perf_counter()
            if m == "ihgr_k3":
                a = s.feed(win)
            else:
                params = cm if m == "ihgr" else ({"max_nodes": max_nodes} if m == "jcbb" else {})
                res = associate_detailed(**s.inputs, method=m, gate_prob=gate_prob, **params)
                a = res.assignment
            dt = time.perf_counter() - t0
            if t < EVAL_FROM_SCAN:
                continue
            st = stats[m]
            if m == "jcbb":
                st["budget_hits"] += int(res.budget_exhausted)
            st["seconds"] += dt
            st["n"] += a.size
            st["correct"] += int((a == s.truth).sum())
            st["false_pair"] += int(((a >= 0) & (a != s.truth)).sum())
            st["missed_pair"] += int(((a < 0) & (s.truth >= 0)).sum())
            unmapped = (s.truth < 0) & (s.truth_landmark >= 0)
            clutter = s.truth_landmark < 0
            st["unmapped"] += int(unmapped.sum())
            st["clutter"] += int(clutter.sum())
            if m == "ihgr_k3":  # -1 seen again in the window: a confirmed new landmark
                conf = (a < 0) & (win.last.sightings >= 2)
                st["unmapped_confirmed"] += int((conf & unmapped).sum())
                st["clutter_confirmed"] += int((conf & clutter).sum())
    return stats


SWEEPS = {
    "clutter": ("clutter_per_scan", "clutter returns per scan", [0.0, 3.0, 10.0, 20.0, 40.0]),
    "density": ("density_per_100m2", "landmarks per 100 m^2", [0.5, 1.0, 2.0, 4.0, 6.0]),
    "pose": ("sigma_xy_m", "pose std (m; heading std = 3.33 deg per m)", [0.1, 0.3, 0.6, 1.0, 1.5]),
}


def rate_trial(cfg: LandmarkSimConfig, seed) -> dict:
    """One simulated sequence of the rate study under `cfg`: `run_methods`' counts."""
    return run_methods(simulate_landmark_scans(cfg, np.random.default_rng(seed)), cfg)


def _sweep_config(base: LandmarkSimConfig, field: str, value: float) -> LandmarkSimConfig:
    if field == "sigma_xy_m":
        return replace(base, sigma_xy_m=value, sigma_heading_rad=math.radians(value * 10.0 / 3.0))
    return replace(base, **{field: value})


def rate_study(
    rng: np.random.Generator,
    n_seq: int,
    base: LandmarkSimConfig | None = None,
    sweeps: dict = SWEEPS,
    progress=lambda d, i, n: None,
    executor=None,
) -> list[dict]:
    """Rows: sweep, value, method, measurements, correct/false/missed rates, ms per scan.

    Every (sweep point, sequence q) is a trial (`rate_trial`) on `executor`. Common random
    numbers: sequence q of every sweep point draws from the same seed, so the points of a sweep
    differ by the swept parameter rather than by the luck of the draw."""
    base = base or LandmarkSimConfig()
    rows = []
    seeds = [np.random.SeedSequence(int(x)) for x in rng.integers(0, 2**63 - 1, n_seq)]
    points = [(name, v) for name, (_f, _l, values) in sweeps.items() for v in values]
    cfgs = {pt: _sweep_config(base, sweeps[pt[0]][0], pt[1]) for pt in points}
    got = (executor or SerialExecutor()).map(
        rate_trial,
        [cfgs[pt] for pt in points for _ in range(n_seq)],
        [seeds[q] for _ in points for q in range(n_seq)],
        desc="association rates",
        progress=progress,
    )
    for j, (name, v) in enumerate(points):
        cfg = cfgs[(name, v)]
        agg: dict = {}
        for st in got[j * n_seq : (j + 1) * n_seq]:
            for m, s in st.items():
                a = agg.setdefault(m, dict.fromkeys(s, 0))
                for k, x in s.items():
                    a[k] += x
        n_scored = n_seq * (cfg.n_scans - EVAL_FROM_SCAN)
        for m, a in agg.items():
            n = max(a["n"], 1)
            rows.append(
                {
                    "sweep": name,
                    "value": v,
                    "method": m,
                    "measurements": a["n"],
                    "correct_rate": a["correct"] / n,
                    "false_pair_rate": a["false_pair"] / n,
                    "missed_pair_rate": a["missed_pair"] / n,
                    "ms_per_scan": 1e3 * a["seconds"] / n_scored,
                    "jcbb_budget_hits": a["budget_hits"],
                    "new_confirmed_rate": a["unmapped_confirmed"] / max(a["unmapped"], 1),
                    "clutter_confirmed_rate": (a["clutter_confirmed"] / max(a["clutter"], 1)),
                }
            )
    return rows


# --------------------------------------------------------------------------------------------
# Optimality: IHGR against the exact integer optimum
# --------------------------------------------------------------------------------------------


def _random_multiscan_instance(rng: np.random.Generator, K: int = 3):
    """A random K-scan set-partitioning instance (Storms and Spieksma's K-dimensional
    assignment): m_k measurements per scan, random tuples of at most one measurement per scan
    with >= 2 members and random costs, a zero-cost singleton per measurement."""
    m = rng.integers(3, 8, K)
    offs = np.concatenate([[0], np.cumsum(m)])
    n_rows = int(offs[-1])
    n_tuples = int(rng.integers(2, 4) * n_rows)
    cols, costs = [], []
    seen = set()
    for _ in range(n_tuples):
        members = tuple(
            int(offs[k] + rng.integers(m[k])) if rng.random() < 0.8 else -1 for k in range(K)
        )
        members = tuple(x for x in members if x >= 0)
        if len(members) < 2 or members in seen:
            continue
        seen.add(members)
        cols.append(members)
        costs.append(-rng.gamma(2.0, 1.0) * len(members) / K)
    for r in range(n_rows):
        cols.append((r,))
        costs.append(0.0)
    rr = np.concatenate([np.asarray(c) for c in cols])
    cc = np.concatenate([np.full(len(c), k) for k, c in enumerate(cols)])
    A = np.zeros((n_rows, len(cols)))
    A[rr, cc] = 1.0
    return np.asarray(costs), A, np.ones(n_rows, bool)


def _single_scan_instances(rng, n):
    out = []
    while len(out) < n:
        cfg = LandmarkSimConfig(
            density_per_100m2=rng.uniform(1.0, 6.0),
            clutter_per_scan=rng.uniform(0, 30),
            sigma_xy_m=rng.uniform(0.3, 1.5),
            n_scans=1,
            sigma_heading_rad=math.radians(rng.uniform(1.0, 5.0)),
        )
        s = simulate_landmark_scans(cfg, rng)[0]
        prep = prepare(**s.inputs, gate_prob=STUDY_GATE_PROB)
        c, A, e, _, _ = single_scan_problem(prep, cost_model_for(cfg))
        out.append((c, A, e))
    return out


def _window_instances(rng, n, empty_map: bool):
    """Set-partitioning problems the K-scan window builds on simulated sequences.

    empty_map: every landmark is unmapped (dense track formation, K = 4), otherwise the
    SLAM-like case (map + 30% unmapped landmarks + heavy clutter, K = 3)."""
    out = []
    while len(out) < n:
        cfg = LandmarkSimConfig(
            density_per_100m2=rng.uniform(1.0, 4.0),
            clutter_per_scan=rng.uniform(5, 30),
            unmapped_fraction=1.0 if empty_map else 0.3,
            sigma_xy_m=rng.uniform(0.2, 1.0),
            n_scans=6,
        )
        K = 4 if empty_map else 3
        win = SlidingWindowAssociator(K=K, model=cost_model_for(cfg), gate_prob=STUDY_GATE_PROB)
        for s in simulate_landmark_scans(cfg, rng):
            s.feed(win)
            if win.last.n_tracks > 0 and len(out) < n:
                out.append(win.last.problem)
    return out


OPT_VARIANTS = {"IHGR": {"fix_ones": False}, "IHGR, also fixing every x = 1": {"fix_ones": True}}


def optimality_trial(instance: tuple, seed=None) -> list[dict]:
    """Solve one instance (`instance` = (family, k, c, A, e)) exactly (milp) and by IHGR (each
    variant; single-scan problems only the default): one row per variant. Deterministic (the
    instance was drawn beforehand), so `seed` is None."""
    fam, k, c, A, e = instance
    t0 = time.perf_counter()
    opt = solve_set_partition(c, A, e, method="milp")
    t_milp = time.perf_counter() - t0
    rows = []
    for vname, opts in OPT_VARIANTS.items():
        if fam.startswith("single") and vname != "IHGR":
            continue
        t0 = time.perf_counter()
        res = solve_set_partition(c, A, e, method="ihgr", presolve=False, **opts)
        t_ihgr = time.perf_counter() - t0
        rows.append(
            {
                "family": fam,
                "variant": vname,
                "instance": k,
                "columns": int(len(c)),
                "rows": int(A.shape[0]),
                "ihgr_cost": res.cost,
                "optimum": opt.cost,
                "lp_bound": res.lp_bound,
                "gap": res.cost - opt.cost,
                "fractional": res.fractional,
                "lp_solves": res.lp_solves,
                "ms_ihgr": 1e3 * t_ihgr,
                "ms_milp": 1e3 * t_milp,
            }
        )
    return rows


def optimality_instances(rng: np.random.Generator, n_per_family: dict[str, int]) -> list[tuple]:
    """The instances of the optimality study, (family, k, c, A, e) each, drawn one family after
    the other from `rng` (as they always were)."""
    families = {
        "single-scan (simulated)": lambda n: _single_scan_instances(rng, n),
        "K=3 window (simulated SLAM)": lambda n: _window_instances(rng, n, empty_map=False),
        "K=4 window, empty map (track formation)": lambda n: _window_instances(rng, n, True),
        "random 3-scan set partitioning": lambda n: [
            _random_multiscan_instance(rng) for _ in range(n)
        ],
    }
    return [
        (fam, k, c, A, e)
        for fam, make in families.items()
        for k, (c, A, e) in enumerate(make(n_per_family[fam]))
    ]


def instances_trial(n_per_family: dict[str, int], seed) -> list[tuple]:
    """`optimality_instances` drawn from `numpy.random.default_rng(seed)`, as a trial: the
    drawing is sequential (one generator for all), so it is one trial, run on a worker beside
    other trials instead of in this process."""
    return optimality_instances(np.random.default_rng(seed), n_per_family)


def optimality_study(
    rng: np.random.Generator,
    n_per_family: dict[str, int],
    progress=lambda d, i, n: None,
    executor=None,
    instances: list[tuple] | None = None,
) -> list[dict]:
    """Rows per instance: family, variant, ihgr cost, optimum, lp bound, fractional, solves.

    The instances are drawn from `rng` (`optimality_instances`; or given, drawn beforehand
    from the same generator by `instances_trial`); solving them, the expensive part, is one
    trial per instance (`optimality_trial`) on `executor`."""
    if instances is None:
        instances = optimality_instances(rng, n_per_family)
    got = (executor or SerialExecutor()).map(
        optimality_trial, instances, desc="association optimality", progress=progress
    )
    return [row for rows in got for row in rows]


def summarise_optimality(rows: list[dict]) -> list[list]:
    out = []
    keys = []
    for r in rows:
        if (r["family"], r["variant"]) not in keys:
            keys.append((r["family"], r["variant"]))
    for fam, var in keys:
        rs = [r for r in rows if r["family"] == fam and r["variant"] == var]
        gap = np.array([r["gap"] for r in rs])
        opt = np.array([r["optimum"] for r in rs])
        tol = 1e-6 * np.maximum(1.0, np.abs(opt))
        frac = np.array([r["fractional"] for r in rs])
        rel = gap / np.maximum(np.abs(opt), 1e-9)
        out.append(
            [
                fam,
                var,
                len(rs),
                round(float(np.mean([r["columns"] for r in rs])), 1),
                float(frac.mean()),
                float((gap <= tol).mean()),
                float((gap <= tol)[frac].mean()) if frac.any() else math.nan,
                float(gap.mean()),
                float(gap.max()),
                float(rel.max()),
                float(np.mean([r["lp_solves"] for r in rs])),
                int(max(r["lp_solves"] for r in rs)),
                float(np.median([r["ms_ihgr"] for r in rs])),
                float(np.median([r["ms_milp"] for r in rs])),
            ]
        )
    return out


OPT_HEADER = [
    "family",
    "variant",
    "instances",
    "mean columns",
    "fractional LP fraction",
    "IHGR optimal fraction",
    "optimal when LP fractional",
    "mean gap (nats)",
    "max gap (nats)",
    "max relative gap",
    "mean LP solves",
    "max LP solves",
    "median ms IHGR",
    "median ms milp",
]


def odd_cycle() -> dict:
    """The issue's rounding example: elements {a, b, c}, sets {ab, bc, ac} cost -1, singletons 0."""
    A = np.array([[1, 0, 1, 1, 0, 0], [1, 1, 0, 0, 1, 0], [0, 1, 1, 0, 0, 1]])
    c = np.array([-1.0, -1.0, -1.0, 0.0, 0.0, 0.0])
    e = np.ones(3, bool)
    r = solve_set_partition(c, A, e, method="ihgr")
    return {
        "lp_bound": r.lp_bound,
        "ihgr_cost": r.cost,
        "lp_solves": r.lp_solves,
        "optimum": solve_set_partition(c, A, e, method="milp").cost,
    }


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------


RATE_LABELS = {
    "sweep_value": "value",
    "correct_rate": "correct rate",
    "false_pair_rate": "false pairing rate",
    "missed_pair_rate": "missed pairing rate",
    "ms_per_scan": "ms per scan",
    "jcbb_budget_hits": "JCBB budget hits",
    "unmapped_confirmed_rate": "unmapped confirmed (K=3)",
    "clutter_confirmed_rate": "clutter confirmed (K=3)",
}


def _rate_records(rows) -> list[dict]:
    """The rate table's records: one per sweep point and method; the JCBB and window columns
    are empty for the other methods."""
    k3 = {"ihgr_k3"}
    return [
        {
            "sweep": r["sweep"],
            "sweep_value": r["value"],
            "method": METHOD_LABELS[r["method"]],
            "measurements": r["measurements"],
            "correct_rate": r["correct_rate"],
            "false_pair_rate": r["false_pair_rate"],
            "missed_pair_rate": r["missed_pair_rate"],
            "ms_per_scan": r["ms_per_scan"],
            "jcbb_budget_hits": r["jcbb_budget_hits"] if r["method"] == "jcbb" else None,
            "unmapped_confirmed_rate": r["new_confirmed_rate"] if r["method"] in k3 else None,
            "clutter_confirmed_rate": r["clutter_confirmed_rate"] if r["method"] in k3 else None,
        }
        for r in rows
    ]


@dataclass(frozen=True)
class RateStudy:
    """The correct-association rate study's results: `rate_study`'s rows, from n_seq
    sequences per point simulated around `base`."""

    base: LandmarkSimConfig
    n_seq: int
    rows: list[dict]


RATE_TABLE = TableSpec(
    "association",
    lambda study: _rate_records(study.rows),
    index=("sweep", "sweep_value", "method"),
    values=None,
    labels=RATE_LABELS,
    title="Correct-association rate on simulated maps",
    notes=lambda study: _rate_notes(study.base, study.n_seq, study.rows),
)


def _loop_table() -> TableSpec:
    """The in-the-loop table (association_loop.csv), of `association_loop.tree_park_loop`'s
    (and `victoria_park_batch`'s) rows; its Markdown is a section of association.md."""
    from experiments.paper import association_loop as al

    return TableSpec(
        "association_loop",
        al.loop_records,
        index=("data", "method"),
        values=None,
        labels=al.LOOP_LABELS,
        notes=al.NOTES,
    )


# the optimality study's instances per family: (--quick, full)
OPTIMALITY_INSTANCES = {
    "single-scan (simulated)": (12, 250),
    "K=3 window (simulated SLAM)": (8, 150),
    "K=4 window, empty map (track formation)": (8, 150),
    "random 3-scan set partitioning": (12, 200),
}


def _sizes(quick: bool) -> tuple[int, dict, dict[str, int]]:
    """(sequences per point, sweeps, optimality instances per family) of the full or the
    quick run (--quick: 2 sequences, each sweep's first, middle and last value)."""
    if not quick:
        return 40, SWEEPS, {fam: n for fam, (_, n) in OPTIMALITY_INSTANCES.items()}
    sweeps = {k: (f, lab, [vals[0], vals[2], vals[-1]]) for k, (f, lab, vals) in SWEEPS.items()}
    return 2, sweeps, {fam: n for fam, (n, _) in OPTIMALITY_INSTANCES.items()}


@experiment("association", order=50, page="association.md", help="IHGR, JCBB and NN side by side")
def run(ctx) -> None:
    """The registered experiment `association`: the rate study and its figure, the methods in
    the SLAM loop (a section of association.md), then the optimality study."""
    cfg_out = ctx.config.setdefault("association", {})
    base = LandmarkSimConfig()
    n_seq, sweeps, n_opt = _sizes(ctx.quick)
    cfg_out.update(
        {
            "sim_defaults": {
                k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(base).items()
            },
            "sequences_per_point": n_seq,
            "scored_scans_per_sequence": base.n_scans - EVAL_FROM_SCAN,
            "sweeps": {k: {"field": f, "values": vals} for k, (f, _, vals) in sweeps.items()},
            "gate_prob": STUDY_GATE_PROB,
            "jcbb_max_nodes": 20_000,
            "window_K": 3,
            "cost_model": "CostModel with the simulator's clutter and unmapped-landmark densities",
            "optimality_instances": n_opt,
        }
    )
    # the optimality study's instances, drawn on a worker while the rate study runs
    opt_rng = ctx.rng("association_optimality")
    drawn = ctx.submit(
        instances_trial,
        [n_opt],
        [opt_rng.bit_generator.seed_seq],
        desc="association optimality instances",
    )
    rows = rate_study(
        ctx.rng("association_rates"),
        n_seq,
        base,
        sweeps,
        progress=ctx.progress,
        executor=ctx.executor,
    )
    labels = {k: lab for k, (_, lab, _) in SWEEPS.items()}
    spec = (
        "association.png",
        association_figures.plot_association,
        (rows,),
        {"method_labels": METHOD_LABELS, "sweep_xlabels": labels},
    )
    products.figures(ctx, [spec], desc="association figure")
    loop_rows, vp_note = _loop_study(ctx, cfg_out)
    _write_rates_and_loop(ctx, RateStudy(base, n_seq, rows), loop_rows, vp_note)
    orows = optimality_study(
        opt_rng, n_opt, ctx.progress, ctx.executor, instances=drawn.result(ctx.progress)[0]
    )
    oc = odd_cycle()
    _write_optimality(ctx, orows, oc)
    cfg_out["odd_cycle"] = oc


def _loop_study(ctx, cfg_out: dict) -> tuple[list[dict], str]:
    """The methods in the SLAM loop (`experiments.paper.association_loop`): (rows, a note when
    Victoria Park was skipped)."""
    from experiments.errors import MissingDataError
    from experiments.paper import association_loop as al

    n_runs, n_scans, vp_scans = (2, 120, 300) if ctx.quick else (al.TREE_PARK_RUNS, None, None)
    # the Victoria Park runs (few and long) first: the tree park's (many, short) fill the
    # workers around them
    vp_note, vp = "", None
    try:
        vp = al.victoria_park_batch(vp_scans, executor=ctx.executor)
    except MissingDataError as exc:
        log.warning("association in the loop: Victoria Park skipped: %s", exc)
        vp_note = f"Victoria Park skipped: {exc}\n"
    rows = al.tree_park_loop(
        ctx.rng("association_loop"),
        n_runs,
        n_scans=n_scans,
        progress=ctx.progress,
        executor=ctx.executor,
    )
    if vp is not None:
        rows += vp.result(ctx.progress)
    cfg_out["in_the_loop"] = {
        "tree_park_runs": n_runs,
        "tree_park_scans": n_scans or 240,
        "odometry_noise_scales": list(al.NOISE_SCALES),
        "victoria_park_scans": vp_scans or "all",
        "methods": [label for label, _, _ in al.LOOP_METHODS],
    }
    return rows, vp_note


def _write_rates_and_loop(ctx, rates: RateStudy, loop_rows: list[dict], vp_note: str) -> None:
    """association.md (the rate table, then the section "In the SLAM loop"), association.csv
    and association_loop.csv."""
    rate_md, rate_csv = RATE_TABLE.texts(rates)
    loop_md, loop_csv = _loop_table().texts(loop_rows)
    md = rate_md + "\n## In the SLAM loop\n\n" + loop_md + vp_note
    ctx.outputs.append(write_atomic(ctx.out_dir / "association.md", md))
    ctx.outputs.append(write_atomic(ctx.out_dir / "association.csv", rate_csv))
    ctx.outputs.append(write_atomic(ctx.out_dir / "association_loop.csv", loop_csv))


def _write_optimality(ctx, orows: list[dict], oc: dict) -> None:
    """association_optimality.md (the summary per family and variant, notes) and .csv (one
    row per instance and variant)."""
    summary = summarise_optimality(orows)
    md = "# IHGR against the exact integer optimum\n\n" + markdown_table(OPT_HEADER, summary)
    md += _optimality_notes(oc, summary)
    ctx.outputs.append(write_atomic(ctx.out_dir / "association_optimality.md", md))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(orows[0]))
    w.writeheader()
    w.writerows(orows)
    ctx.outputs.append(write_atomic(ctx.out_dir / "association_optimality.csv", buf.getvalue()))


def _rate_notes(base: LandmarkSimConfig, n_seq: int, rows) -> str:
    return (
        f"{n_seq} simulated sequences per point, {base.n_scans} scans each; scans "
        f"{EVAL_FROM_SCAN + 1}..{base.n_scans} are scored (the first ones warm up the K = 3 "
        "window). Defaults: "
        f"{base.density_per_100m2} landmarks per 100 m^2 ({base.unmapped_fraction:.0%} not in "
        f"the map), {base.clutter_per_scan} clutter returns per scan, pose std "
        f"{base.sigma_xy_m} m / {math.degrees(base.sigma_heading_rad):.1f} deg, landmark std "
        f"{base.sigma_landmark_m} m, P_D {base.p_detect}, noise {base.sigma_range_m} m / "
        f"{math.degrees(base.sigma_bearing_rad):.1f} deg, range {base.max_range_m} m over "
        f"360 deg, landmarks at least {base.min_separation_m} m apart. Sequence q of every "
        "sweep point uses the same seed (common random numbers). The pose error is common to "
        "a sequence and no EKF update shrinks it (a stress case for methods that treat "
        "pairings as independent).\n\n"
        "- correct: the measurement gets its true map feature, or -1 when it is clutter or an "
        "unmapped landmark.\n"
        "- false pairing: paired with a feature that is not its own (the error that corrupts an "
        "EKF); missed pairing: a mapped landmark returned as -1.\n"
        "- IHGR uses the negative-log-likelihood costs of `association.CostModel` with the "
        "simulator's clutter and unmapped-landmark densities; JCBB and NN only gate "
        "(chi-square 0.99). JCBB node budget 20000; 'JCBB budget hits' counts scans where it "
        "ran out and fell back to the best hypothesis found.\n"
        "- IHGR K = 3: `SlidingWindowAssociator` fed the estimated sensor pose, with twice the "
        "per-scan odometry drift as its relative covariance. 'unmapped confirmed': fraction of "
        "the measurements of unmapped landmarks that it returned as -1 with sightings >= 2 "
        "(seen again within the window: a new landmark to initialise); 'clutter confirmed': "
        "the same fraction for clutter returns (false confirmations). Single-scan methods "
        "cannot tell these two kinds of -1 apart.\n"
        "- ms per scan: mean wall time of the call, on the machine that wrote this file.\n"
    )


def _optimality_notes(oc: dict, summary) -> str:
    return (
        "\nGap = IHGR cost - optimal cost, in nats (negative log-likelihood); relative gap "
        "divides by |optimum|. 'fractional LP' = the first LP relaxation had a fractional "
        "vertex. IHGR runs here without presolve, so every instance goes through linprog "
        "(HiGHS dual simplex). Variants: 'IHGR' (the default) fixes the largest fractional "
        "variable in each pass; 'also fixing every x = 1' fixes, in the same pass, every "
        "variable the LP already put at 1 (the faster variant of docs/method.md section 1).\n\n"
        "Families: single-scan problems from simulated scans with strong contention (1-6 "
        "landmarks per 100 m^2, up to 30 clutter returns, pose std up to 1.5 m); the problems "
        "`SlidingWindowAssociator` builds on simulated sequences (K = 3 with a map, 30% unmapped "
        "landmarks and heavy clutter; K = 4 with an empty map, where every landmark must be "
        "found by track formation); random 3-scan set partitioning (random tuples with random "
        "negative costs, zero-cost singletons): the K-dimensional assignment of Storms and "
        "Spieksma, which is NP-hard.\n\n"
        f"Odd cycle (elements a, b, c; sets ab, bc, ac at -1; singletons at 0): LP bound "
        f"{oc['lp_bound']:.3f}, IHGR cost {oc['ihgr_cost']:.3f} after {oc['lp_solves']} LP "
        f"solves, optimum {oc['optimum']:.3f}.\n"
    )

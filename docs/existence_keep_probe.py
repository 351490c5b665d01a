"""Victoria Park, scans 1-2000: why the existence map policy misses reference trees, and the map
with tentatives kept through their misses (`map_policy.existence_keep_tentatives`, issue 41).
A script, not part of the package; the figures of the lab notebook's entry "Landmark
existence: tentatives kept through their misses" were measured with it once.

    TRUNKSLAM_DATA=/work/shared/datasets .venv/bin/python -P docs/existence_keep_probe.py \
        detections --out /tmp/keep_detections.json
    (the same with paper, geometric; --variants to run a subset)
    .venv/bin/python -P docs/existence_keep_probe.py sim --out /tmp/keep_sim.json

    TRUNKSLAM_DATA=/work/shared/datasets .venv/bin/python -P docs/existence_keep_probe.py \
        full --variants "persistent, kept, q derived" --out /tmp/keep_full.json

reach (`--reach-of` an extractor): the established landmarks' detection rate by range and free
beams on each half of the confirm run (`existence_rates.range_detection_rates`), then per
variant and derivation the seen reference trees by fate with what their misses were, from
`LandmarkExistence.trace` (`diagnose_reach`); table (`--logs` of reach runs): those rows as
the lab notebook's markdown tables (entry "why held-out trees are still missed").

full: the whole Victoria Park run (7249 scans, published detections, IHGR, closure off: the
preset as `reproduce victoria-park` runs it) with the existence policy and the settings derived
on scans 1-2000 of the detections' confirm run, the first variant named: `real_run._one`'s row
(GPS RMSE over the vouched fixes, landmarks, map precision and recall over scans 1-2000).

(-P: docs/experiments/, the site's pages, would shadow the package.)

The variants ending in "footprint" count a see-through beam only when its footprint, half the
beam step (HALF_STEP) + k sd_bearing, lies inside the trunk (`existence_see_through_footprint`),
with q derived with the same count; "q by range" takes q per 10 m range bin
(`derive_see_through_by_range`); "repeat by range" takes persistent clutter's repeat rate per
10 m range bin (`derive_repeat_by_range`), not scaled by Pd's fall-off; "birth by range" a
new track's birth per 10 m bin of its first circle's range (`derive_birth_by_range`). The
lab notebook's entry "a see-through beam's footprint, and the see-through rate by range" was
measured with them once (before "repeat by range" existed).

sim: `reproduce sim-clutter`'s 20 drives (its seeds: root seed 0), both scenes, `paper` and
`geometric`: the confirm run, then the existence policy with the settings derived from it
(as `sim_clutter._existence_row`, persistent clutter included) for each variant; precision and
recall pooled over the drives as the sim-clutter table pools them.

Per extractor (the published detections, or `paper` / `geometric` on the raw scans), as
`victoria_park.existence_policy` does: one run of scans 1-2000 with the preset and the paper's
confirm_scans 3; from it, without the reference or the GPS, the existence settings of each half
and of the whole (`existence_rates.derive_existence`, and `derive_persistent` for the
persistent clutter); then one run of scans 1-2000 per variant (uniform / persistent clutter,
tentatives dropped at a miss / kept) and per derivation (derived on 1-1000 judged on
1001-2000, the other way round, and 1-2000 as a whole), judged by `reference_match`.

The reference trees serve the diagnosis only (no setting reads them): of the reference trees a
circle the filter considered came within 1 m of in the judged scans and no landmark of the map
is within 1 m of, what became of the tracks of those circles, the furthest any got:
"left the map by existence", "mapped > 1 m away" (a landmark of the map, not within 1 m of the
tree), "tentative: existence below remove_prob", "tentative dropped at a miss", "tentative
pending at the end", "circles never a track of their own" (paired with another landmark, or
ambiguous). Tentatives' fates are recorded by wrapping `Tentatives.step` (which ids left the
set, and whether their existence or a miss dropped them).
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from scipy.stats import chi2

from experiments.eval.existence_rates import (
    MAX_BEAMS,
    derive_birth_by_range,
    derive_existence,
    derive_pd_range,
    derive_persistent,
    derive_repeat_by_range,
    derive_see_through,
    derive_see_through_by_range,
    range_detection_rates,
)
from experiments.eval.map_quality import reference_in_our_frame
from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
from experiments.paper.victoria_park.existence_policy import _features, _judge, _tag
from experiments.paper.victoria_park.real_run import HALVES, run_config
from slam import SlamConfig, existence_map, run_slam, se2
from slam import tentatives as tentatives_module
from slam.log import OUT_OF_RANGE, SKIPPED

# the see-through tolerance's k: sqrt(chi2_2(0.95)), the half-width of the 95% ellipse's
# projection on an axis (`slam.existence`, "See-through tolerance")
K95 = math.sqrt(float(chi2.ppf(0.95, 2)))
# the beam footprint of the see-through count: half the beam step, the ray's own angular
# uncertainty (`slam.existence`, "Beam footprint"; the data state no beam divergence)
HALF_STEP = 0.5

# the settings the four persistent, kept, bounded, fused variants with the tolerance share
TOLERANT = {
    "map_policy.existence_clutter": "persistent",
    "map_policy.existence_keep_tentatives": True,
    "map_policy.existence_unreached_scans": 100,
    "map_policy.existence_fuse_tentatives": True,
    "map_policy.existence_see_through_k": K95,
}
VARIANTS = {
    "uniform": {},
    "uniform, kept": {"map_policy.existence_keep_tentatives": True},
    "persistent": {"map_policy.existence_clutter": "persistent"},
    "persistent, kept": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
    },
    # diagnosis only (not a derived setting): how much of the loss the see-through factor is
    "persistent, kept, q 1": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_see_through_q": 1.0,
    },
    "uniform, kept, q 1": {
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_see_through_q": 1.0,
    },
    # see_through_q derived on the derivation half (`existence_rates.derive_see_through`)
    "persistent, kept, q derived": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
        "q": "derived",
    },
    "uniform, kept, q derived": {"map_policy.existence_keep_tentatives": True, "q": "derived"},
    # the kept tentatives bounded: dropped after UNREACHED scans out of every beam's reach
    "persistent, kept, q derived, bounded": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_unreached_scans": 100,
        "q": "derived",
    },
    # Pd's range fall-off derived on the derivation half (`existence_rates.derive_pd_range`)
    "persistent, kept, q derived, range, bounded": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_unreached_scans": 100,
        "q": "derived",
        "range": "derived",
    },
    "uniform, kept, q derived, range, bounded": {
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_unreached_scans": 100,
        "q": "derived",
        "range": "derived",
    },
    # a tentative placed by its sightings fused (`existence_fuse_tentatives`), and the
    # see-through tolerance at the 95% region (`existence_see_through_k`, K95; not tuned)
    "persistent, kept, q derived, range, bounded, fused": {
        "map_policy.existence_clutter": "persistent",
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_unreached_scans": 100,
        "map_policy.existence_fuse_tentatives": True,
        "q": "derived",
        "range": "derived",
    },
    "persistent, kept, q derived, range, bounded, fused, tolerance": {
        **TOLERANT,
        "q": "derived",
        "range": "derived",
    },
    # a see-through beam's footprint (half the beam step, + k sd_bearing) inside the trunk
    # (`existence_see_through_footprint`), q derived with the same count
    "persistent, kept, q derived, range, bounded, fused, tolerance, footprint": {
        **TOLERANT,
        "map_policy.existence_see_through_footprint": HALF_STEP,
        "q": "derived",
        "range": "derived",
    },
    # see_through_q per 10 m range bin, derived on the derivation half
    # (`existence_rates.derive_see_through_by_range`; with the footprint: its count)
    "persistent, kept, q by range, range, bounded, fused, tolerance": {
        **TOLERANT,
        "q": "by range",
        "range": "derived",
    },
    "persistent, kept, q by range, range, bounded, fused, tolerance, footprint": {
        **TOLERANT,
        "map_policy.existence_see_through_footprint": HALF_STEP,
        "q": "by range",
        "range": "derived",
    },
    # persistent clutter's repeat rate per 10 m range bin, derived on the derivation half
    # (`existence_rates.derive_repeat_by_range`): a far sighting weighs Pd(d) / repeat(d)
    "persistent, kept, q by range, range, bounded, fused, tolerance, footprint, repeat by range": {
        **TOLERANT,
        "map_policy.existence_see_through_footprint": HALF_STEP,
        "q": "by range",
        "range": "derived",
        "repeat": "by range",
    },
    # and the birth per 10 m range bin of the circle that starts a track, derived on the
    # derivation half (`existence_rates.derive_birth_by_range`)
    "persistent, kept, q by range, range, bounded, fused, tolerance, footprint, repeat by range, "
    "birth by range": {
        **TOLERANT,
        "map_policy.existence_see_through_footprint": HALF_STEP,
        "q": "by range",
        "range": "derived",
        "repeat": "by range",
        "birth": "by range",
    },
    "uniform, kept, q derived, range, bounded, fused, tolerance": {
        "map_policy.existence_keep_tentatives": True,
        "map_policy.existence_unreached_scans": 100,
        "map_policy.existence_fuse_tentatives": True,
        "map_policy.existence_see_through_k": K95,
        "q": "derived",
        "range": "derived",
    },
}


def _settings(derived: dict, variant: str) -> dict:
    """The variant's settings: the derived ones, its own, and the derived see_through_q where
    it asks for it."""
    own = dict(VARIANTS[variant])
    footprint = own.get("map_policy.existence_see_through_footprint", 0.0) > 0
    how = own.pop("q", None)
    if how in ("derived", "by range"):
        q = derived["see_through_q_footprint" if footprint else "see_through_q"]
        own["map_policy.existence_see_through_q"] = q
    if how == "by range":
        own |= derived["q_by_range_footprint" if footprint else "q_by_range"]
    if own.pop("range", None) == "derived":
        own |= derived["pd_range"]
    if own.pop("repeat", None) == "by range":
        own |= derived["repeat_by_range"]
    if own.pop("birth", None) == "by range":
        own |= derived["birth_by_range"]
    mine = ("see_through_q", "see_through_q_footprint", "pd_range", "q_by_range")
    mine += ("q_by_range_footprint", "repeat_by_range", "birth_by_range")
    return {k: v for k, v in derived.items() if k not in mine} | own


FATES = (
    "left the map by existence",
    "mapped > 1 m away",
    "tentative: existence below remove_prob",
    "tentative dropped at a miss",
    "tentative pending at the end",
    "circles never a track of their own",
)


class _Fates:
    """Wraps `Tentatives.step`: id -> "existence" / "miss" for every tentative that left the
    set other than by joining the map."""

    def __init__(self) -> None:
        self.dropped: dict[int, str] = {}
        self._step = tentatives_module.Tentatives.step

    def __enter__(self):
        fates, step = self, self._step

        def wrapped(tent, matched, new, scan_index, policy, join=None, gone=None):
            out, confirm = step(tent, matched, new, scan_index, policy, join=join, gone=gone)
            left = set(tent.ids.tolist()) - set(out.ids.tolist())
            left -= {int(tent.ids[i]) for i in confirm}
            for i in np.flatnonzero(np.isin(tent.ids, list(left))):
                by_existence = gone is not None and bool(np.asarray(gone)[i])
                fates.dropped[int(tent.ids[i])] = "existence" if by_existence else "miss"
            return out, confirm

        tentatives_module.Tentatives.step = wrapped
        return self

    def __exit__(self, *exc) -> None:
        tentatives_module.Tentatives.step = self._step


def _trees(lg, ref) -> np.ndarray:
    n = min(ref[0].shape[0], lg.n_scans)
    ours = np.array([se2.compose(p, lg.laser_pose)[:2] for p in lg.pose[:n]])
    return reference_in_our_frame(ours, *ref)


def _fate(tracks: set, lg, dropped: dict) -> str:
    gone = {int(row[0]) for row in (lg.departures or [])}
    mapped = set(lg.landmark_id.tolist())
    if tracks & gone:
        return FATES[0]
    if tracks & mapped:
        return FATES[1]
    reasons = {dropped.get(t) for t in tracks}
    if "existence" in reasons:
        return FATES[2]
    if "miss" in reasons:
        return FATES[3]
    return FATES[4] if tracks else FATES[5]


def diagnose(lg, ref, dropped: dict, scans: tuple[int, int]) -> dict:
    """The missed reference trees of `scans` by the fate of their circles' tracks (module doc),
    with the scans their circles were seen in (median, by fate)."""
    tw = _trees(lg, ref)
    used = (lg.meas_status != OUT_OF_RANGE) & (lg.meas_status != SKIPPED)
    used &= (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1])
    rows = np.flatnonzero(used)
    xy = se2.observed_points(lg.pose[lg.meas_scan[rows]], lg.meas_z[rows], lg.laser_pose)
    d_circle = np.linalg.norm(xy[:, None, :] - tw[None, :, :], axis=2)  # (circles, trees)
    if lg.landmark_xy.size:
        d_map = np.linalg.norm(lg.landmark_xy[:, None, :] - tw[None, :, :], axis=2).min(axis=0)
    else:
        d_map = np.full(tw.shape[0], math.inf)
    seen = (d_circle <= 1.0).any(axis=0)
    out: dict = {f: [] for f in FATES}
    for t in np.flatnonzero(seen & (d_map > 1.0)):
        near = rows[d_circle[:, t] <= 1.0]
        tracks = {int(x) for x in lg.meas_track[near] if x >= 0}
        out[_fate(tracks, lg, dropped)].append(int(np.unique(lg.meas_scan[near]).size))
    return {
        "seen_trees": int(seen.sum()),
        "missed": {f: len(v) for f, v in out.items()},
        "scans_seen_median": {f: float(np.median(v)) for f, v in out.items() if v},
        "tentatives_dropped": {
            r: sum(1 for v in dropped.values() if v == r) for r in ("miss", "existence")
        },
    }


def _base(extractor: str):
    """The extractor's confirm_scans 3 run of scans 1-2000 and the settings derived on each half
    and on the whole: (seq, ref, base config, features, run, {tag: settings})."""
    seq = load_victoria_park(n_scans=2000)
    ref = load_ss2002_reference()
    base = run_config(extractor, "ihgr").with_(
        **{"map_policy.confirm_scans": 3, "map_policy.prune_after_expected": 0}
    )
    feats = _features(seq, extractor, base)
    lg = run_slam(seq, base, features=feats)
    whole = (0, 2000)
    derived = {}
    for h in (*HALVES, whole):
        settings = derive_existence(lg, seq, h)["settings"]
        settings |= derive_persistent(lg, h)["settings"]
        min_beams = settings["map_policy.existence_min_beams"]
        q = derive_see_through(lg, seq, h, min_beams)["settings"]
        derived[_tag(h)] = settings | {"see_through_q": q["map_policy.existence_see_through_q"]}
        qf = derive_see_through(lg, seq, h, min_beams, footprint_steps=HALF_STEP)["settings"]
        derived[_tag(h)]["see_through_q_footprint"] = qf["map_policy.existence_see_through_q"]
        for key, f in (("q_by_range", 0.0), ("q_by_range_footprint", HALF_STEP)):
            qr = derive_see_through_by_range(lg, seq, h, min_beams, footprint_steps=f)
            derived[_tag(h)][key] = qr["settings"]
        derived[_tag(h)]["pd_range"] = derive_pd_range(lg, seq, h, min_beams)["settings"]
        derived[_tag(h)]["repeat_by_range"] = derive_repeat_by_range(lg, seq, h)["settings"]
        derived[_tag(h)]["birth_by_range"] = derive_birth_by_range(lg, seq, h)["settings"]
    return seq, ref, base, feats, lg, derived


def probe(extractor: str, variants: list[str]) -> dict:
    t0 = time.time()
    seq, ref, base, feats, lg, derived = _base(extractor)
    out = {"extractor": extractor, "derived": derived, "base_s": time.time() - t0, "rows": []}
    a, b = (_tag(h) for h in HALVES)
    for variant in variants:
        for fit, judged in ((a, b), (b, a), ("1_2000", "1_2000")):
            cfg = base.with_(
                **{"map_policy.policy": "existence", **_settings(derived[fit], variant)}
            )
            t0 = time.time()
            with _Fates() as fates:
                run = run_slam(seq, cfg, features=feats)
            lo, hi = (int(x) for x in judged.split("_"))
            row = {
                "variant": variant,
                "derived_on": fit,
                "judged_on": judged,
                **_judge(run, ref, judged),
                "removed": len(run.departures or []),
                "seconds": round(time.time() - t0, 1),
                "diagnosis": diagnose(run, ref, fates.dropped, (lo - 1, hi)),
            }
            print(json.dumps(row), flush=True)
            out["rows"].append(row)
    return out


def _sim_drive(seed: int, variants: list[str]) -> list[dict]:
    from experiments.paper.sim_clutter import SCENES, _map_figures
    from experiments.paper.slam import Exp2Config
    from experiments.paper.slam import run_config as exp2_config
    from experiments.sim.clutter import clutter_park
    from experiments.sim.scene import load_scene
    from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
    from features import extract_features

    rows = []
    for name in SCENES:
        scene = clutter_park() if name.endswith("_clutter") else load_scene(name)
        seq = simulate_cycab_run(
            np.random.default_rng(seed), scene, CycabParams(**MONTE_CARLO_PATH)
        )
        for m in ("paper", "geometric"):
            scfg = exp2_config(Exp2Config(), m).with_(**{"features.extractor.short_trunks": False})
            kw = scfg.features.extractor_kwargs()
            feats = [extract_features(seq.scan(k), m, **kw) for k in range(seq.n_scans)]
            lg = run_slam(seq, scfg, features=feats)
            settings = derive_existence(lg, seq, (0, seq.n_scans))["settings"]
            settings |= derive_persistent(lg, (0, seq.n_scans))["settings"]
            mb = settings["map_policy.existence_min_beams"]
            q = derive_see_through(lg, seq, (0, seq.n_scans), mb)["settings"]
            settings["see_through_q"] = q["map_policy.existence_see_through_q"]
            n = (0, seq.n_scans)
            qf = derive_see_through(lg, seq, n, mb, footprint_steps=HALF_STEP)["settings"]
            settings["see_through_q_footprint"] = qf["map_policy.existence_see_through_q"]
            for key, f in (("q_by_range", 0.0), ("q_by_range_footprint", HALF_STEP)):
                qr = derive_see_through_by_range(lg, seq, n, mb, footprint_steps=f)
                settings[key] = qr["settings"]
            settings["pd_range"] = derive_pd_range(lg, seq, n, mb)["settings"]
            settings["repeat_by_range"] = derive_repeat_by_range(lg, seq, n)["settings"]
            settings["birth_by_range"] = derive_birth_by_range(lg, seq, n)["settings"]
            for variant in variants:
                cfg = scfg.with_(
                    **{"map_policy.policy": "existence", **_settings(settings, variant)}
                )
                ex = run_slam(seq, cfg, features=feats)
                row = {"scene": name, "method": m, "variant": variant, "seed": seed}
                rows.append(row | _map_figures(ex, scene, seq, feats))
    return rows


def sim(variants: list[str], runs: int = 20) -> dict:
    from experiments.paper.runner import experiment_seed

    seeds = np.random.default_rng(experiment_seed(0, "sim-clutter")).integers(0, 2**31, size=runs)
    rows = []
    for seed in seeds.tolist():
        rows += _sim_drive(int(seed), variants)
        print(f"drive {len(rows)} rows", flush=True)
    pooled = []
    for key in sorted({(r["scene"], r["method"], r["variant"]) for r in rows}):
        rs = [r for r in rows if (r["scene"], r["method"], r["variant"]) == key]
        total = sum(r["landmarks"] for r in rs)
        pooled.append(
            {
                "scene": key[0],
                "method": key[1],
                "variant": key[2],
                "precision": sum(r["right"] for r in rs) / total if total else math.nan,
                "recall": sum(r["trunks_found"] for r in rs) / sum(r["trunks"] for r in rs),
                "landmarks_mean": total / len(rs),
                "on_bushes_mean": sum(r["landmarks_bush"] for r in rs) / len(rs),
                "on_people_mean": sum(r["landmarks_person"] for r in rs) / len(rs),
            }
        )
    return {"pooled": pooled, "rows": rows}


def full(variant: str) -> dict:
    from experiments.paper.victoria_park.real_run import _one

    seq2000 = load_victoria_park(n_scans=2000)
    base = run_config("detections", "ihgr")
    confirm = base.with_(**{"map_policy.confirm_scans": 3, "map_policy.prune_after_expected": 0})
    lg = run_slam(seq2000, confirm)
    h = (0, 2000)
    settings = derive_existence(lg, seq2000, h)["settings"] | derive_persistent(lg, h)["settings"]
    mb = settings["map_policy.existence_min_beams"]
    q = derive_see_through(lg, seq2000, h, mb)["settings"]
    settings["see_through_q"] = q["map_policy.existence_see_through_q"]
    qf = derive_see_through(lg, seq2000, h, mb, footprint_steps=HALF_STEP)["settings"]
    settings["see_through_q_footprint"] = qf["map_policy.existence_see_through_q"]
    for key, f in (("q_by_range", 0.0), ("q_by_range_footprint", HALF_STEP)):
        qr = derive_see_through_by_range(lg, seq2000, h, mb, footprint_steps=f)
        settings[key] = qr["settings"]
    settings["pd_range"] = derive_pd_range(lg, seq2000, h, mb)["settings"]
    settings["repeat_by_range"] = derive_repeat_by_range(lg, seq2000, h)["settings"]
    settings["birth_by_range"] = derive_birth_by_range(lg, seq2000, h)["settings"]
    cfg = base.with_(**{"map_policy.policy": "existence", **_settings(settings, variant)})
    row, run, _ = _one(variant, load_victoria_park(full=True), cfg, load_ss2002_reference())
    keep = ("rmse_vouched_m", "fixes_vouched", "rmse_m", "fixes", "rmse_2001_7249_m")
    keep += ("landmarks", "precision_1m", "reference_trees_seen_1m", "nis_inside", "seconds")
    out = {k: row[k] for k in keep} | {"variant": variant, "settings": settings}
    out["removed"] = len(run.departures or [])
    print(json.dumps(out), flush=True)
    return out


RANGE_EDGES = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 80.0])
BEAM_BINS = ((1, 1), (2, 2), (3, 3), (4, 5), (6, 9), (10, MAX_BEAMS))


def rate_table(lg, seq, half: tuple[int, int]) -> dict:
    """The established landmarks' detection rate on `half` by range bin (RANGE_EDGES) and free
    beams (BEAM_BINS): `existence_rates.range_detection_rates`, printed as a matrix."""
    e, d = range_detection_rates(lg, seq, half, RANGE_EDGES)
    cells = {}
    for i in range(RANGE_EDGES.size - 1):
        for lo, hi in BEAM_BINS:
            n, k = int(e[i, lo : hi + 1].sum()), int(d[i, lo : hi + 1].sum())
            cells[f"{RANGE_EDGES[i]:g}-{RANGE_EDGES[i + 1]:g} m, {lo}-{hi} beams"] = (k, n)
    return {"expected": e.tolist(), "detected": d.tolist(), "cells": cells}


class _Traces:
    """Makes every `LandmarkExistence` of the runs inside record its updates (`trace`)."""

    def __init__(self) -> None:
        self.books: list = []
        self._init = existence_map.LandmarkExistence.__init__

    def __enter__(self):
        books, init = self.books, self._init

        def wrapped(book, *args, **kw):
            init(book, *args, **kw)
            book.trace = []
            books.append(book)

        existence_map.LandmarkExistence.__init__ = wrapped
        return self

    def __exit__(self, *exc) -> None:
        existence_map.LandmarkExistence.__init__ = self._init

    def flat(self) -> dict:
        tr = self.books[-1].trace
        return {k: np.concatenate([np.asarray(t[k]) for t in tr]) for k in tr[0] if k != "scan"} | {
            "scan_of": np.concatenate([np.full(len(t["id"]), t["scan"]) for t in tr])
        }


def _logit(r: np.ndarray) -> np.ndarray:
    r = np.clip(r, 1e-300, 1.0 - 1e-16)
    return np.log(r) - np.log1p(-r)


def _track_stats(tr: dict, tracks: set, q: float, e, d) -> dict:
    """Over the existence updates of `tracks`: sightings, charged misses (Pd > 0, not detected),
    and what the misses were: range, see-through, occlusion, log-odds lost (and the see-through
    factor's part), the detection rate the deriving half measured at the misses' (range, free
    beams) cells, and the detections the model (pd) and that rate expect over the scans the
    model said it could be seen in."""
    rows = np.isin(tr["id"], list(tracks))
    det, pd = tr["detected"][rows], tr["pd"][rows]
    reach = pd > 0
    miss = reach & ~det
    rb, ra = tr["r_before"][rows], tr["r_after"][rows]
    ok = np.isfinite(rb)
    dlo = np.where(ok, _logit(ra) - _logit(np.where(ok, rb, 0.5)), 0.0)
    rng, free = tr["range_m"][rows], np.minimum(tr["free"][rows], MAX_BEAMS)
    b = np.clip(np.searchsorted(RANGE_EDGES, rng, side="right") - 1, 0, RANGE_EDGES.size - 2)
    rate = np.where(e[b, free] > 0, d[b, free] / np.maximum(e[b, free], 1), np.nan)
    through = tr["through"][rows]
    return {
        "sightings": int(det.sum()),
        "misses": int(miss.sum()),
        "misses_see_through": int((miss & (through > 0)).sum()),
        "misses_occluded_in_part": int((miss & (tr["reach"][rows] > tr["free"][rows])).sum()),
        "misses_beyond_30m": int((miss & (rng >= 30.0)).sum()),
        "logodds_misses": float(dlo[miss].sum()),
        "logodds_see_through": float((through[miss] * math.log(q)).sum()),
        "logodds_sightings": float(dlo[det].sum()),
        "expected_by_model": float(pd[reach].sum()),
        "expected_by_rate": float(np.nansum(rate[reach])),
        "rate_at_misses": float(np.nanmean(rate[miss])) if miss.any() else math.nan,
        "range_at_misses_median": float(np.median(rng[miss])) if miss.any() else math.nan,
        # the existence after the tracks' last update (the latest scan any of them was updated)
        "r_last": float(ra[np.argmax(tr["scan_of"][rows])]) if rows.any() else math.nan,
    }


def diagnose_reach(lg, ref, dropped: dict, scans, tr: dict, q: float, e, d) -> dict:
    """The seen reference trees of `scans` by fate ("found": a landmark within 1 m), and per
    fate the sums of `_track_stats` over their circles' tracks."""
    tw = _trees(lg, ref)
    used = (lg.meas_status != OUT_OF_RANGE) & (lg.meas_status != SKIPPED)
    used &= (lg.meas_scan >= scans[0]) & (lg.meas_scan < scans[1])
    rows = np.flatnonzero(used)
    xy = se2.observed_points(lg.pose[lg.meas_scan[rows]], lg.meas_z[rows], lg.laser_pose)
    d_circle = np.linalg.norm(xy[:, None, :] - tw[None, :, :], axis=2)
    d_map = np.linalg.norm(lg.landmark_xy[:, None, :] - tw[None, :, :], axis=2).min(axis=0)
    out: dict = {}
    per_tree: list = []
    for t in np.flatnonzero((d_circle <= 1.0).any(axis=0)):
        tracks = {int(x) for x in lg.meas_track[rows[d_circle[:, t] <= 1.0]] if x >= 0}
        fate = "found" if d_map[t] <= 1.0 else _fate(tracks, lg, dropped)
        st = _track_stats(tr, tracks, q, e, d)
        if fate != "found":
            per_tree.append({"fate": fate, "cause": _cause(fate, st)} | st)
        acc = out.setdefault(fate, {"trees": 0})
        acc["trees"] += 1
        for k, v in st.items():
            if k in ("rate_at_misses", "range_at_misses_median"):
                acc.setdefault(k, []).append(v)
            else:
                acc[k] = acc.get(k, 0) + v
    for acc in out.values():
        for k in ("rate_at_misses", "range_at_misses_median"):
            v = np.array(acc[k])
            acc[k] = float(np.nanmedian(v)) if np.isfinite(v).any() else math.nan
    causes = [t["cause"] for t in per_tree]
    return out | {"causes": {c: causes.count(c) for c in CAUSES}, "missed_trees": per_tree}


CAUSES = (
    "out of reach before joining (unreached bound)",
    "sightings weighed against it",
    "see-through beams: most of the misses' loss",
    "misses without see-through: seen too rarely",
    "mapped > 1 m away",
    "tentative pending at the end",
    "no track of its own",
    "dropped at a miss",
)


REMOVE_PROB = SlamConfig().map_policy.existence_remove_prob  # the variants keep the default


def _cause(fate: str, st: dict) -> str:
    """A missed tree's cause (CAUSES): a tentative dropped with its existence still at or above
    remove_prob was dropped by the unreached bound; for the trees their existence dropped (a
    tentative below remove_prob, or a landmark that left the map), whether their sightings
    gained nothing in log-odds (persistent clutter's object hypothesis fits them as well), or
    else whether the see-through factor's part (n log q) is more than half of what their
    charged misses cost; otherwise their fate."""
    if fate == "tentative: existence below remove_prob" and st["r_last"] >= REMOVE_PROB:
        return CAUSES[0]  # dropped by existence_unreached_scans, its existence above the bar
    if fate in ("left the map by existence", "tentative: existence below remove_prob"):
        lost, seen_through = st["logodds_misses"], st["logodds_see_through"]
        if st["logodds_sightings"] <= 0:
            return CAUSES[1]
        return CAUSES[2] if lost < 0 and seen_through < 0.5 * lost else CAUSES[3]
    return {
        "mapped > 1 m away": CAUSES[4],
        "tentative pending at the end": CAUSES[5],
        "circles never a track of their own": CAUSES[6],
    }.get(fate, CAUSES[7])


def reach(extractor: str, variants: list[str]) -> dict:
    """The detection rates by range and free beams of each half, and per variant and half the
    seen reference trees by fate with what their misses were (`diagnose_reach`)."""
    seq, ref, base, feats, lg, derived = _base(extractor)
    tables = {_tag(h): rate_table(lg, seq, h) for h in (*HALVES, (0, 2000))}
    for tag, t in tables.items():
        print(tag, json.dumps(t["cells"]), flush=True)
    out = {"extractor": extractor, "derived": derived, "tables": tables, "rows": []}
    a, b = (_tag(h) for h in HALVES)
    for variant in variants:
        for fit, judged in ((a, b), (b, a), ("1_2000", "1_2000")):
            settings = _settings(derived[fit], variant)
            cfg = base.with_(**{"map_policy.policy": "existence", **settings})
            t0 = time.time()
            with _Fates() as fates, _Traces() as traces:
                run = run_slam(seq, cfg, features=feats)
            lo, hi = (int(x) for x in judged.split("_"))
            e, d = (np.array(tables[fit][k]) for k in ("expected", "detected"))
            q = float(cfg.map_policy.existence_see_through_q)
            row = {
                "variant": variant,
                "derived_on": fit,
                "judged_on": judged,
                **_judge(run, ref, judged),
                "removed": len(run.departures or []),
                "tentatives_max": int(run.n_tentative.max()),
                "tentatives_at_end": int(run.n_tentative[-1]),
                "seconds": round(time.time() - t0, 1),
                "fates": diagnose_reach(
                    run, ref, fates.dropped, (lo - 1, hi), traces.flat(), q, e, d
                ),
            }
            print(json.dumps(row), flush=True)
            out["rows"].append(row)
    return out


def _bailey() -> dict:
    """(derived_on, judged_on) tags -> `bailey`'s (precision, recall) with confirm_scans derived
    on the same half: the snapshot's docs/results/victoria_park_split_half.csv (the reference
    precision of issue 41)."""
    import csv
    from pathlib import Path

    path = Path(__file__).resolve().parent / "results" / "victoria_park_split_half.csv"
    out = {}
    with open(path) as fh:
        for row in csv.DictReader(fh):
            if row["extractor"] == "bailey":
                tags = [x.split()[1].split("-") for x in (row["derived_on"], row["judged_on"])]
                key = tuple(f"{lo}_{hi}" for lo, hi in tags)
                out[key] = (float(row["precision"]), float(row["recall"]))
    return out


def table(logs: list[str]) -> dict:
    """The halves table and the missed trees' misses, as markdown, from `reach` logs (their
    printed rows; extractor: the log's name after "reach_")."""
    rows = []
    for path in logs:
        ex = path.rsplit("reach_", 1)[-1].split(".")[0]
        with open(path) as fh:
            rows += [{"extractor": ex} | json.loads(x) for x in fh if x.startswith('{"variant"')]
    bailey = _bailey()
    print(
        "| extractor | variant | derived on | judged on | P / R (landmarks) | tentatives, max "
        "| `bailey` P / R (confirm_scans derived) |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        b = bailey[(r["derived_on"], r["judged_on"])]
        print(
            f"| {r['extractor']} | {r['variant']} | {r['derived_on']} | {r['judged_on']} | "
            f"{r['precision']:.3f} / {r['recall']:.3f} ({r['landmarks']}) | {r['tentatives_max']} "
            f"| {b[0]:.3f} / {b[1]:.3f} |"
        )
    print()
    print(
        "| extractor | variant | judged on | fate | trees | sightings | misses | with see-through "
        "| occluded in part | beyond 30 m | log-odds: sightings / misses (see-through part) "
        "| rate measured at the misses | median range of the misses (m) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        for fate, v in r["fates"].items():
            if fate in ("causes", "missed_trees"):
                continue
            print(
                f"| {r['extractor']} | {r['variant']} | {r['judged_on']} | {fate} | {v['trees']} "
                f"| {v['sightings']} | {v['misses']} | {v['misses_see_through']} "
                f"| {v['misses_occluded_in_part']} | {v['misses_beyond_30m']} "
                f"| {v['logodds_sightings']:+.0f} / {v['logodds_misses']:+.0f} "
                f"({v['logodds_see_through']:+.0f}) | {v['rate_at_misses']:.2f} "
                f"| {v['range_at_misses_median']:.1f} |"
            )
    print()
    print(
        "| extractor | variant | derived on | judged on | missed | "
        + " | ".join(CAUSES)
        + " | see-through ones: landmarks that left the map | their misses' median range (m) |"
    )
    print("|---|---|---|---|---|" + "---|" * (len(CAUSES) + 2))
    for r in rows:
        c = r["fates"].get("causes")
        if c is None:
            continue
        see = [t for t in r["fates"]["missed_trees"] if t["cause"] == CAUSES[2]]
        left = sum(t["fate"] == "left the map by existence" for t in see)
        rng = np.nanmedian([t["range_at_misses_median"] for t in see]) if see else math.nan
        print(
            f"| {r['extractor']} | {r['variant']} | {r['derived_on']} | {r['judged_on']} "
            f"| {sum(c.values())} | "
            + " | ".join(str(c[k]) for k in CAUSES)
            + f" | {left} | {rng:.1f} |"
        )
    return {"rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "extractor", choices=("detections", "paper", "geometric", "sim", "full", "reach", "table")
    )
    ap.add_argument("--logs", nargs="*", default=[], help="table: the reach runs' logs")
    ap.add_argument("--reach-of", default="detections", help="reach: the extractor")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS)[:4], choices=list(VARIANTS))
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    if args.extractor == "sim":
        res = sim(args.variants)
    elif args.extractor == "table":
        res = table(args.logs)
    elif args.extractor == "reach":
        res = reach(args.reach_of, args.variants)
    elif args.extractor == "full":
        res = full(args.variants[0])
    else:
        res = probe(args.extractor, args.variants)
    with open(args.out, "w") as fh:
        json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()

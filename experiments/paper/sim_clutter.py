"""Experiment `sim-clutter`: the map's precision and recall per object class in a simulated park
with the objects that fool the extractor on real data (`experiments.sim.clutter`).

Each run drives the Cycab once around the tree park (Table 3's drive: `CycabParams` with
`MONTE_CARLO_PATH`, 240 scans) twice, with the same seed: through the park as it is and
through `clutter_park()` (the same park with lamp posts and sign poles far away, parked cars,
two more bushes and three standing people). Every extractor of Table 3 (`paper`,
`geometric`, `bailey`) runs experiment 2's filter (`experiments.paper.slam.run_config`,
IHGR) on each, and `paper` and `geometric` again with short trunks on (`VARIANTS`: the
extractor's default and the Victoria Park preset's; experiment 2 runs the paper's extractor
without them).

A landmark's class is the class (`CLUTTER_CLASSES`) of the object most of its measurements'
beams hit (the per-beam truth); it is right when that object is a trunk and the landmark lies
within `MATCH_M` of the trunk's centre (the 0.5 m of Table 4's false features). Precision:
right landmarks over all landmarks; recall: trunks with a right landmark over all trunks. Per
class: the landmarks of that class and the objects of the class that some landmark holds.
Posts and legs are circles, but they are not trees: a trunk map that holds them is wrong.
"""

from __future__ import annotations

import logging

import numpy as np

from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.slam import METHODS, Exp2Config, run_config
from experiments.sim.clutter import CLUTTER_CLASSES, clutter_park
from experiments.sim.scene import load_scene
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import run_slam

__all__ = ["CLASSES", "MATCH_M", "RUNS", "clutter_trial", "landmark_objects", "run"]

log = logging.getLogger(__name__)

NAME = "sim-clutter"
RUNS, QUICK_RUNS = 20, 2
MATCH_M = 0.5  # Table 4's false_match_m
CLASSES = ("trunk", "post", "car", "bush", "person", "wall", "none")
SCENES = ("tree_park", "tree_park_clutter")
# (label, extractor, short_trunks): Table 3's extractors as experiment 2 runs them (the paper's,
# without short trunks), and `paper` and `geometric` with short trunks on, as the Victoria Park
# preset and the extractor's defaults run them
VARIANTS = (
    *((m, m, False) for m in METHODS),
    ("paper, short trunks", "paper", True),
    ("geometric, short trunks", "geometric", True),
)
# Table 3's extractors again with map policy "existence" (`slam.existence_map`), its settings
# derived from the same drive's confirm_scans run without the truth
# (`experiments.eval.existence_rates.derive_existence` over all its scans)
EXISTENCE = tuple(m for m, _, short in VARIANTS if not short)
# and with persistent clutter (`existence_clutter = "persistent"`), its repeat_prob and
# shape_sd_m derived from the same confirm run (`existence_rates.derive_persistent`)
PERSISTENT = "existence, persistent clutter"
LABELS_RUN = (
    *(v[0] for v in VARIANTS),
    *(f"{m}, existence" for m in EXISTENCE),
    *(f"{m}, {PERSISTENT}" for m in EXISTENCE),
)


def landmark_objects(lg, labels: np.ndarray, feats) -> dict[int, int]:
    """{landmark id: the scene label most of its measurements' beams hit} (landmarks whose
    beams hit nothing labelled are left out). labels: (T, B) the run's per-beam truth."""
    tracks = lg.meas_track if lg.meas_track_unmerged is None else lg.meas_track_unmerged
    votes: dict[int, list] = {}
    n_beams = labels.shape[1]
    for r in np.flatnonzero(tracks >= 0):
        k, f = int(lg.meas_scan[r]), int(lg.meas_feature[r])
        a, b = feats[k].circle_beams[f]
        hit = labels[k, np.arange(a, b + 1) % n_beams]
        hit = hit[hit >= 0]
        if hit.size:
            votes.setdefault(int(tracks[r]), []).append(int(np.bincount(hit).argmax()))
    return {t: int(np.bincount(v).argmax()) for t, v in votes.items()}


def _map_figures(lg, scene, seq, feats) -> dict:
    """One run's map against the scene's truth (module doc)."""
    obj = landmark_objects(lg, seq.scan_labels, feats)
    trunks = set(scene.truth_trunks.tolist())
    kinds = [o.kind for o in scene.objects]
    out = {f"landmarks_{c}": 0 for c in CLASSES} | {f"objects_{c}": 0 for c in CLASSES}
    out |= {f"mapped_{c}": 0 for c in CLASSES}
    for k in kinds:
        out[f"objects_{CLUTTER_CLASSES[k]}"] += 1
    right, held, found = 0, set(), set()
    for lid, xy in zip(lg.landmark_id.tolist(), lg.landmark_xy):
        lab = obj.get(int(lid))
        cls = "none" if lab is None else CLUTTER_CLASSES[kinds[lab]]
        out[f"landmarks_{cls}"] += 1
        if lab is None:
            continue
        held.add(lab)
        if lab in trunks and np.hypot(*(xy - scene.circles[lab].center_xy)) <= MATCH_M:
            right += 1
            found.add(lab)
    for lab in held:
        out[f"mapped_{CLUTTER_CLASSES[kinds[lab]]}"] += 1
    out["landmarks"] = int(lg.landmark_id.size)
    out["right"] = right
    out["trunks"] = len(trunks)
    out["trunks_found"] = len(found)
    return out


def clutter_trial(job: tuple, seed) -> list[dict]:
    """Run `job` = (index,): the drive of `seed` through each scene of `SCENES`, every method:
    one record per (scene, method)."""
    (index,) = job
    cfg = Exp2Config()
    rows = []
    for name in SCENES:
        scene = clutter_park() if name.endswith("_clutter") else load_scene(name)
        seq = simulate_cycab_run(
            np.random.default_rng(seed), scene, CycabParams(**MONTE_CARLO_PATH)
        )
        for label, m, short in VARIANTS:
            scfg = run_config(cfg, m).with_(**{"features.extractor.short_trunks": short})
            kw = scfg.features.extractor_kwargs()
            feats = [extract_features(seq.scan(k), m, **kw) for k in range(seq.n_scans)]
            lg = run_slam(seq, scfg, features=feats)
            rows.append(
                {"scene": name, "method": label, "run": index} | _map_figures(lg, scene, seq, feats)
            )
            if label in EXISTENCE:
                run = (scene, seq, scfg, feats)
                rows.append(_existence_row(name, label, index, run, lg))
                rows.append(_existence_row(name, label, index, run, lg, persistent=True))
    return rows


def _existence_row(name: str, label: str, index: int, run: tuple, lg, persistent=False) -> dict:
    """The drive again with map policy "existence", its settings derived from `lg` (the
    confirm_scans run of the same drive) without the truth; persistent: with persistent
    clutter, its settings derived from `lg` as well."""
    from experiments.eval.existence_rates import derive_existence, derive_persistent

    scene, seq, scfg, feats = run
    settings = derive_existence(lg, seq, (0, seq.n_scans))["settings"]
    if persistent:
        settings |= {"map_policy.existence_clutter": "persistent"}
        settings |= derive_persistent(lg, (0, seq.n_scans))["settings"]
    cfg = scfg.with_(**{"map_policy.policy": "existence", **settings})
    ex = run_slam(seq, cfg, features=feats)
    tag = f"{label}, {PERSISTENT}" if persistent else f"{label}, existence"
    row = {"scene": name, "method": tag, "run": index}
    return row | _map_figures(ex, scene, seq, feats)


def summary_records(rows: list[dict]) -> list[dict]:
    """Per scene and method: precision and recall over all runs (pooled), and per class the
    landmarks per run and the share of the class's objects mapped."""
    out = []
    for scene in SCENES:
        for m in LABELS_RUN:
            rs = [r for r in rows if r["scene"] == scene and r["method"] == m]
            if not rs:
                continue
            total = sum(r["landmarks"] for r in rs)
            rec = {
                "scene": scene,
                "method": m,
                "runs": len(rs),
                "precision": sum(r["right"] for r in rs) / total if total else float("nan"),
                "recall": sum(r["trunks_found"] for r in rs) / sum(r["trunks"] for r in rs),
                "landmarks_mean": total / len(rs),
            }
            for c in CLASSES:
                rec[f"landmarks_{c}_mean"] = sum(r[f"landmarks_{c}"] for r in rs) / len(rs)
            for c in CLASSES[:-1]:  # "none" is no object
                n_obj = sum(r[f"objects_{c}"] for r in rs)
                rec[f"mapped_{c}"] = (
                    sum(r[f"mapped_{c}"] for r in rs) / n_obj if n_obj else float("nan")
                )
            out.append(rec)
    return out


_PLURAL = {
    "trunk": "trunks",
    "post": "posts",
    "car": "cars",
    "bush": "bushes",
    "person": "people's legs",
    "wall": "walls",
    "none": "nothing labelled",
}
LABELS = {
    "runs": "runs",
    "precision": "precision",
    "recall": "recall",
    "landmarks_mean": "landmarks, mean",
    **{f"landmarks_{c}_mean": f"on {p}, mean" for c, p in _PLURAL.items()},
    **{f"mapped_{c}": f"{p} held (share)" for c, p in _PLURAL.items() if c != "none"},
}
PARTS = (
    ("Precision and recall", ("runs", "precision", "recall", "landmarks_mean")),
    (
        "Landmarks by the class of what their beams hit",
        tuple(f"landmarks_{c}_mean" for c in CLASSES),
    ),
    ("Objects of each class held by a landmark", tuple(f"mapped_{c}" for c in CLASSES[:-1])),
)
TABLE = TableSpec(
    "sim_clutter",
    summary_records,
    index=("scene", "method"),
    values=tuple(LABELS),
    parts=PARTS,
    labels=LABELS,
    title="Simulated tree park with the clutter of real data: the map by object class",
    notes=(
        "experiments/paper/sim_clutter.py; objects and their sizes: experiments/sim/clutter.py. "
        "Each run: one drive of Table 3 (240 scans) through the tree park and, with the same "
        "seed, through the park with clutter (6 posts and poles, 3 cars, 2 more bushes, 3 "
        'people), experiment 2\'s filter with each extractor, IHGR ("short trunks": the '
        "extractor's short_trunks on, as the Victoria Park preset). A landmark's class: that of "
        "the object most of its measurements' beams hit; precision: landmarks on a trunk within "
        f"{MATCH_M} m of its centre over all landmarks (pooled over the runs); recall: trunks so "
        "held over all trunks. A share of a class mapped: its objects held by some landmark."
    ),
)


@experiment(
    "sim-clutter",
    order=130,
    page="sim-clutter.md",
    help="the map by object class in a simulated park with posts, cars, bushes and people "
    "(only when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `sim-clutter` (only when named)."""
    n = QUICK_RUNS if ctx.quick else RUNS
    seeds = ctx.rng(NAME).integers(0, 2**31, size=n).tolist()
    batch = ctx.submit(clutter_trial, [(i,) for i in range(n)], seeds, desc="sim-clutter runs")

    def finish(records: list) -> None:
        rows = [r for rs in records for r in rs]
        ctx.config[NAME] = {"runs": n, "match_m": MATCH_M}
        products.tables(ctx, [TABLE], rows)

    ctx.later(batch, finish)

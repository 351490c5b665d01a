"""Experiment `victoria-park-split-half`: the map figures of scans 1-2000 judged on a half that
no setting saw.

The map policy's `confirm_scans` (`map_policy.derive_confirm`) is chosen by the map's F1
against the 2002 SLAM school's reference trees, and the preset's value (4) was chosen on
scans 1-2000, the very trees and scans its precision and recall are then reported on: those
figures are in-sample. Here the same documented procedure runs on one half of scans 1-2000
(`victoria_park.HALVES`) and the figures are reported on the other:

1. One run of scans 1-2000 per candidate confirm_scans (`map_policy.CONFIRM_CANDIDATES`,
   published detections, IHGR, pruning off: `map_policy`'s sweep) and one per extractor
   and candidate (`bailey`, `paper`, `geometric` on the raw scans, the preset's extractor
   parameters, `victoria_park.run_config`). Each map is judged by
   `victoria_park.reference_match` on each half: precision (landmarks that joined in the half
   with a reference tree within 1 m) and recall (of the reference trees a circle the filter
   considered came within 1 m of in the half, those with a landmark within 1 m).
2. The setting of a half: `derive_confirm` on the published detections' F1 of that half alone
   (the rule of the map policy: highest F1, inside the candidates, a tie to the fewer scans).
   No figure of the other half enters it.
3. Reported: every extractor's precision, recall and F1 on the other half with that setting;
   and, marked in-sample, the figure of scans 1-2000 as a whole with the preset's setting.

What the halves share: the run is one run of scans 1-2000, so a landmark that joined in scans
1-1000 is placed with what scans 1001-2000 saw of it too (data, never the reference), and a
tree seen in both halves counts in the recall of both (`overlap_trees` in the manifest says
how many). Settings that cannot be derived without the reference map (an F1 whose maximum is
at an end of the candidates) are reported as not derived and are not adopted.
"""

from __future__ import annotations

import logging
import math

from experiments.errors import DataError, MissingDataError
from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from experiments.paper.victoria_park.map_policy import CONFIRM_CANDIDATES, derive_confirm, f1_score
from experiments.paper.victoria_park.real_run import HALVES, reference_match, run_config
from slam import run_slam

__all__ = ["EXTRACTORS", "derive_per_half", "split_half_rows", "split_trial", "run"]

log = logging.getLogger(__name__)

NAME = "victoria-park-split-half"
FIT_SCANS = 2000
EXTRACTORS = ("detections", "bailey", "paper", "geometric")  # "detections": the published ones
_FEATURES: dict = {}  # (extractor, scans) -> features, shared by a worker's trials


def _half_tag(half: tuple[int, int]) -> str:
    return f"{half[0] + 1}_{half[1]}"


def _features(seq, extractor: str, cfg):
    """The extractor's circles of every scan of `seq` (None for the published detections)."""
    if extractor == "detections":
        return None
    key = (extractor, seq.n_scans)
    if key not in _FEATURES:
        from features import extract_features

        kw = cfg.features.extractor_kwargs()
        _FEATURES[key] = [
            extract_features(seq.scan(k), extractor, **kw) for k in range(seq.n_scans)
        ]
    return _FEATURES[key]


def split_trial(job: tuple, seed=None) -> dict:
    """One run (`job` = (extractor, confirm_scans, n_scans)) of the first n_scans raw scans,
    judged on scans 1-2000 and on each half: its record (deterministic; the seed is unused)."""
    extractor, k, n_scans = job
    seq = load_victoria_park(n_scans=n_scans)
    ref = load_ss2002_reference()
    cfg = run_config(extractor, "ihgr").with_(
        **{"map_policy.confirm_scans": int(k), "map_policy.prune_after_expected": 0}
    )
    lg = run_slam(seq, cfg, features=_features(seq, extractor, cfg))
    m = reference_match(lg, lg.laser_pose, *ref)
    row = {"extractor": extractor, "confirm_scans": int(k), "landmarks": int(lg.landmark_id.size)}
    row |= {"precision": m["precision_1m"], "recall": m["reference_trees_seen_1m"]}
    for half in HALVES:
        t = _half_tag(half)
        row[f"precision_{t}"] = m[f"precision_{t}"]
        row[f"recall_{t}"] = m[f"reference_trees_seen_1m_{t}"]
        row[f"landmarks_{t}"] = int(
            ((lg.landmark_first_scan >= half[0]) & (lg.landmark_first_scan < half[1])).sum()
        )
    for t in ("", *(f"_{_half_tag(h)}" for h in HALVES)):
        row[f"f1{t}"] = f1_score(row[f"recall{t}"], row[f"precision{t}"])
    return row


def derive_per_half(records: list[dict]) -> dict[str, int | None]:
    """{half tag: the confirm_scans `derive_confirm` picks from the published detections' F1 of
    that half alone, or None when the rule cannot pick one (its maximum at an end)}."""
    det = [r for r in records if r["extractor"] == "detections"]
    out: dict[str, int | None] = {}
    for half in HALVES:
        t = _half_tag(half)
        try:
            out[t] = derive_confirm(
                [{"confirm_scans": r["confirm_scans"], "f1": r[f"f1_{t}"]} for r in det]
            )
        except DataError as exc:
            log.warning("%s: half %s: %s", NAME, t, exc)
            out[t] = None
    return out


def split_half_rows(records: list[dict], derived: dict, preset_confirm: int) -> list[dict]:
    """The table's rows: per extractor, each half judged with the setting derived on the other
    (NaN figures when that setting could not be derived), and scans 1-2000 with the preset's
    setting (in-sample)."""
    by = {(r["extractor"], r["confirm_scans"]): r for r in records}
    (a, b) = (_half_tag(h) for h in HALVES)
    rows = []
    for ex in EXTRACTORS:
        for fit, judged in ((a, b), (b, a), ("1_2000", "1_2000")):
            k = preset_confirm if fit == "1_2000" else derived.get(fit)
            r = by.get((ex, k)) if k is not None else None
            t = "" if judged == "1_2000" else f"_{judged}"
            figures = {
                name: (r[f"{name}{t}"] if r is not None else math.nan)
                for name in ("precision", "recall", "f1", "landmarks")
            }
            rows.append(
                {
                    "extractor": ex,
                    "derived_on": f"scans {fit.replace('_', '-')}",
                    "judged_on": f"scans {judged.replace('_', '-')}"
                    + (" (in-sample)" if fit == judged else ""),
                    "confirm_scans": math.nan if k is None else k,
                    **figures,
                }
            )
    return rows


LABELS = {
    "confirm_scans": "confirm_scans",
    "landmarks": "landmarks",
    "precision": "precision",
    "recall": "recall",
    "f1": "F1",
}
TABLE = TableSpec(
    "victoria_park_split_half",
    lambda rows: rows,
    index=("extractor", "derived_on", "judged_on"),
    values=tuple(LABELS),
    labels=LABELS,
    title="Victoria Park: map figures judged on a half no setting saw (scans 1-2000)",
    notes=(
        "experiments/paper/victoria_park/split_half.py. confirm_scans derived by the map "
        "policy's rule "
        "(highest F1 of the published detections' map against the 2002 reference, inside the "
        "candidates 2-6) on one half of scans 1-2000 and reported on the other; the last row "
        "of each extractor: the preset's confirm_scans (derived on scans 1-2000) judged on "
        "scans 1-2000, in-sample. One run of scans 1-2000 per extractor and confirm_scans, "
        "IHGR, pruning off. Precision: landmarks that joined in the judged scans with a "
        "reference tree within 1 m; recall: of the reference trees a circle came within 1 m "
        "of in the judged scans, those with a landmark within 1 m; landmarks: those that "
        "joined in the judged scans."
    ),
)


@experiment(
    "victoria-park-split-half",
    order=140,
    page="victoria-park.md",
    help="Victoria Park map figures judged on a half of scans 1-2000 no setting saw (needs the "
    "data; only when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `victoria-park-split-half` (only when named; needs the data;
    --quick: scans 1-2000 with the candidates 3-5 only)."""
    try:
        load_ss2002_reference()
        load_victoria_park(n_scans=10)
    except MissingDataError as exc:
        log.warning("Victoria Park split-half skipped: %s", exc)
        ctx.config[NAME] = f"skipped: {exc}"
        return
    from experiments.io.config_file import load_slam_config, preset_path

    preset = load_slam_config(preset_path("victoria_park_ute")).map_policy.confirm_scans
    candidates = (3, 4, 5) if ctx.quick else CONFIRM_CANDIDATES
    jobs = [(ex, k, FIT_SCANS) for ex in EXTRACTORS for k in candidates]
    batch = ctx.submit(split_trial, jobs, desc="split-half runs", chunksize=1)
    from experiments.paper.victoria_park import existence_policy

    existence_policy.submit(ctx, EXTRACTORS, FIT_SCANS, NAME)  # the existence policy's rows

    def finish(records: list) -> None:
        derived = derive_per_half(records)
        ctx.config[NAME] = {
            "scans": FIT_SCANS,
            "candidates": list(candidates),
            "preset_confirm_scans": preset,
            **{f"confirm_scans_derived_on_{t}": k for t, k in derived.items()},
        }
        products.tables(ctx, [TABLE], split_half_rows(records, derived, preset))

    ctx.later(batch, finish)

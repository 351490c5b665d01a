"""The existence map policy on Victoria Park (`map_policy.policy = "existence"`, issue 41): its
parameters derived from a run itself, without the reference map or the GPS, on one half of
scans 1-2000, and its map judged on the other (rows of `victoria-park-split-half`).

Per extractor, one job (`existence_trial`):
1. A base run of scans 1-2000 with the preset and the paper's map policy (confirm_scans 3,
   `MapPolicy`'s default: no figure of the reference chose it; pruning off).
2. From it, on the scans of a half (`derive_existence`), reference-free:
   - Pd from the detection rates the run measures (`beam_detection_rates`): every landmark of
     the final map associated in more than `existence_rates.ESTABLISHED` scans, in each scan of the
     half after it joined, placed by the run's pose in the laser frame, counts as expected with
     the number of its beams that reach its width unoccluded (`slam.existence.beam_evidence`
     with its circles' median radius), and as detected when a measurement updated it.
     min_beams: the fewest free beams whose detection rate is at least half the rate of the
     well-seen (>= `WELL_SEEN` free beams); pd_max: the rate pooled over min_beams and more.
   - the clutter: false_per_scan, the circles the filter considered in the half (not out of
     range, not ambiguous) whose track never became a landmark of the map, per scan used.
     Chosen over the simulator's false-detection rate (Table 4) because it is the extractor's
     rate on this park's clutter, which the simulated parks do not have.
   - birth_prob: of the tracks started in the half, the share that joined the map.
   join_prob 0.99 and remove_prob 0.01 keep their meaning (`MapPolicy`); nothing is tuned on a
   map figure.
3. Three runs of scans 1-2000 with the existence policy: with the settings of each half, judged
   on the other half (`reference_match`'s precision and recall of that half), and with those of
   scans 1-2000 judged on the whole.
"""

from __future__ import annotations

from experiments.eval.existence_rates import derive_existence
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.victoria_park.map_policy import f1_score
from experiments.paper.victoria_park.real_run import HALVES, reference_match, run_config
from slam.config import MapPolicy

__all__ = ["BASE_CONFIRM", "TABLE", "existence_rows", "existence_trial", "submit"]

BASE_CONFIRM = 3  # the paper's confirm_scans, MapPolicy's default: no reference chose it


def _features(seq, extractor: str, cfg):
    """The extractor's circles of every scan of `seq` (None for the published detections)."""
    if extractor == "detections":
        return None
    from features import extract_features

    kw = cfg.features.extractor_kwargs()
    return [extract_features(seq.scan(k), extractor, **kw) for k in range(seq.n_scans)]


def _tag(half: tuple[int, int]) -> str:
    return f"{half[0] + 1}_{half[1]}"


def _judge(lg, ref, tag: str) -> dict:
    m = reference_match(lg, lg.laser_pose, *ref)
    if tag == "1_2000":
        p, r = m["precision_1m"], m["reference_trees_seen_1m"]
        n = int(lg.landmark_id.size)
    else:
        a, b = (int(x) for x in tag.split("_"))
        p, r = m[f"precision_{tag}"], m[f"reference_trees_seen_1m_{tag}"]
        first = lg.landmark_first_scan
        n = int(((first >= a - 1) & (first < b)).sum())
    return {"precision": p, "recall": r, "f1": f1_score(r, p), "landmarks": n}


def existence_trial(job: tuple, seed=None) -> dict:
    """One extractor's job (`job` = (extractor, n_scans)): the base run, the settings derived
    on each half and on the whole, the three existence runs judged (module doc)."""
    from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
    from slam import run_slam

    extractor, n_scans = job
    seq = load_victoria_park(n_scans=n_scans)
    ref = load_ss2002_reference()
    base = run_config(extractor, "ihgr").with_(
        **{"map_policy.confirm_scans": BASE_CONFIRM, "map_policy.prune_after_expected": 0}
    )
    feats = _features(seq, extractor, base)
    lg = run_slam(seq, base, features=feats)
    whole = (0, min(n_scans, HALVES[-1][1]))
    derived = {_tag(h): derive_existence(lg, seq, h) for h in (*HALVES, whole)}
    a, b = (_tag(h) for h in HALVES)
    out = {"extractor": extractor, "derived": derived, "rows": []}
    for fit, judged in ((a, b), (b, a), (_tag(whole), _tag(whole))):
        cfg = base.with_(**{"map_policy.policy": "existence", **derived[fit]["settings"]})
        run = run_slam(seq, cfg, features=feats)
        row = {
            "extractor": extractor,
            "derived_on": f"scans {fit.replace('_', '-')}",
            "judged_on": f"scans {judged.replace('_', '-')}"
            + (" (in-sample)" if fit == judged else ""),
            **_judge(run, ref, judged),
            "removed": len(run.departures or []),
        }
        row |= {k.split(".")[1]: v for k, v in derived[fit]["settings"].items()}
        out["rows"].append(row)
    return out


def existence_rows(results: list[dict]) -> list[dict]:
    """The table's rows from the jobs' results."""
    return [r for res in results for r in res["rows"]]


_POLICY = MapPolicy()  # the thresholds the runs use: the defaults (module doc)
LABELS = {
    "landmarks": "landmarks",
    "precision": "precision",
    "recall": "recall",
    "f1": "F1",
    "removed": "removed by existence",
    "existence_pd_max": "pd_max",
    "existence_min_beams": "min_beams",
    "existence_false_per_scan": "false circles per scan",
    "existence_birth_prob": "birth_prob",
}
TABLE = TableSpec(
    "victoria_park_split_half_existence",
    lambda rows: rows,
    index=("extractor", "derived_on", "judged_on"),
    values=tuple(LABELS),
    labels=LABELS,
    title="Victoria Park: the existence map policy, derived on a half and judged on the other",
    notes=(
        "experiments/paper/victoria_park/existence_policy.py. map_policy.policy = existence "
        f"with join_prob {_POLICY.existence_join_prob:g} and remove_prob "
        f"{_POLICY.existence_remove_prob:g}; pd_max, min_beams, the false circles per "
        "scan and birth_prob measured without the reference or the GPS "
        "(experiments/eval/existence_rates.py) on the scans of derived_on of a run with the "
        "paper's confirm_scans 3, then one run of scans 1-2000 with them, judged on the other "
        "half (the last row of each extractor: derived and judged on scans 1-2000, in-sample). "
        "Precision, recall and landmarks as in the table above; removed: landmarks that left "
        "the map by their existence in the whole run."
    ),
)


def submit(ctx, extractors: tuple, n_scans: int, name: str) -> None:
    """The jobs of `victoria-park-split-half`'s existence rows, and their table once done."""
    batch = ctx.submit(
        existence_trial,
        [(ex, n_scans) for ex in extractors],
        desc="split-half existence runs",
        chunksize=1,
    )

    def finish(results: list) -> None:
        ctx.config[f"{name}-existence"] = {
            r["extractor"]: {t: d["settings"] for t, d in r["derived"].items()} for r in results
        }
        products.tables(ctx, [TABLE], existence_rows(results))

    ctx.later(batch, finish)

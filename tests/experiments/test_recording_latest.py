"""A recording shows at every scan what it showed when every scan logged every entity: the
recorder leaves out a row of no item (points, strips, circles) after a row of none at the same
entity (`viz.Recorder._put_items`), and rerun shows at each time the latest row at or before
it, component by component. Read back from the files: at each scan, each entity's latest value
of each component is the same as in a recording of every row."""

from __future__ import annotations

import numpy as np
import pytest
from rerun.chunk import RrdReader

from experiments.eval.series import slam_panels, slam_series
from experiments.io.config_file import load_slam_config
from experiments.render import viz
from experiments.sim import CycabParams, simulate_cycab_run
from experiments.sim.landmarks import avenue
from slam import SlamConfig, run_slam


class _EveryRow(viz.Recorder):
    """The recorder before the rule: every row logged, empty or not."""

    def _put_items(self, path, spec, n, *values) -> None:
        self._put(path, spec, *values)


def _latest_at_each_scan(path, n_scans: int) -> tuple[dict, dict]:
    """({entity: [{component: latest value at or before scan k} for k < n_scans]}, {entity:
    rows}) of the scene entities (the series are logged whole, `log_series`); static rows
    apart, as their own entry."""
    rows: dict[str, list] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        entity = str(chunk.entity_path)
        if entity.startswith("/series") or entity.startswith("/__"):
            continue
        data = chunk.to_record_batch().to_pydict()
        comps = [c for c in data if ":" in c]
        for i in range(chunk.num_rows):
            k = data["scan"][i] if "scan" in data else -1
            rows.setdefault(entity, []).append((k, {c: data[c][i] for c in comps}))
    shown = {}
    for entity, logged in rows.items():
        logged.sort(key=lambda r: r[0])  # (stable: rows of one scan keep their order)
        latest, at, j = {}, [], 0
        for k in range(-1, n_scans):
            while j < len(logged) and logged[j][0] <= k:
                latest.update({c: v for c, v in logged[j][1].items() if v is not None})
                j += 1
            at.append(repr(sorted(latest.items())))
        shown[entity] = at
    return shown, {e: len(r) for e, r in rows.items()}


def _tree_park():
    seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=60))
    return seq, None, SlamConfig().with_(**{"features.method": "geometric"})


def _avenue():  # features given as circle centres: no segment, line or edge at any scan
    seq, feats = avenue(40, np.random.default_rng(0))
    return seq, feats, load_slam_config("cycab")


@pytest.mark.parametrize("drive", [_tree_park, _avenue])
def test_a_recording_shows_at_each_scan_what_every_row_showed(drive, tmp_path):
    seq, feats, cfg = drive()
    files = {}
    for name, kind in (("ours", viz.Recorder), ("every", _EveryRow)):
        files[name] = tmp_path / f"{name}.rrd"
        with kind(files[name], series=slam_panels(seq.truth_t is not None)) as rec:
            lg = run_slam(seq, cfg, features=feats, visualiser=rec)
            rec.log_series(lg.scan_t, slam_series(lg, seq.truth_t, seq.truth_pose))
    ours, ours_rows = _latest_at_each_scan(files["ours"], seq.n_scans)
    every, every_rows = _latest_at_each_scan(files["every"], seq.n_scans)
    assert ours.keys() == every.keys()
    for entity in every:
        assert ours[entity] == every[entity], entity
    fewer = {e for e in every_rows if ours_rows[e] < every_rows[e]}
    assert "/world/tentative" in fewer or "/world/associations" in fewer
    assert fewer <= {
        "/world/tentative",
        "/world/associations",
        *(f"/world/laser/features/{p}" for p in ("segments", "circles", "lines", "edges")),
    }
    if feats is not None:  # never a segment: one row, at the first scan
        assert ours_rows["/world/laser/features/segments"] == 1
        assert every_rows["/world/laser/features/segments"] == seq.n_scans

"""What a SLAM recording holds of the map: the landmarks (centres and ids) at every scan, and
their 95% ellipses when a landmark joined or left the map, else once `viz.ELLIPSES_EVERY_S`
seconds of the sequence's time have passed since they were last logged, and at the last scan,
whole: the map a viewer shows at the end of a run is the run's final map."""

from __future__ import annotations

import numpy as np
import pytest
from rerun.chunk import RrdReader

from experiments.render import viz
from experiments.render.shapes import ellipse_polylines
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamConfig, run_slam

CFG = SlamConfig().with_(**{"features.method": "geometric", "association.method": "ihgr"})
SCALE = 10.0


class _Seen:
    """A visualiser that keeps what the run gave `log_landmarks` at each scan, and passes every
    call on to `rec`."""

    def __init__(self, rec):
        self.rec = rec
        self.maps: dict[int, tuple] = {}
        self.stamps: dict[int, float] = {}

    def set_scan(self, k, stamp_s=None):
        self.k = k
        self.stamps[k] = stamp_s
        self.rec.set_scan(k, stamp_s)

    def log_landmarks(self, xy, cov, ids):
        self.maps[self.k] = (np.array(xy), np.array(cov), np.array(ids))
        self.rec.log_landmarks(xy, cov, ids)

    def __getattr__(self, name):
        return getattr(self.rec, name)


def _entity_rows(path, entity: str) -> dict[int, list]:
    out = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        if str(chunk.entity_path) == entity:
            d = chunk.to_record_batch().to_pydict()
            column = next(k for k in d if k.endswith(":strips") or k.endswith(":positions"))
            for k, value in zip(d["scan"], d[column]):
                out[k] = value
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    path = tmp_path_factory.mktemp("map") / "run.rrd"
    seq = simulate_cycab_run(np.random.default_rng(7), "tree_park", CycabParams(n_scans=100))
    seen = _Seen(viz.Recorder(path, ellipse_scale=SCALE))
    run_slam(seq, CFG, visualiser=seen)
    seen.rec.close()
    return path, seen


def test_landmarks_every_scan_and_ellipses_by_the_rule(recorded):
    path, seen = recorded
    points = _entity_rows(path, "/world/landmarks")
    ellipses = _entity_rows(path, "/world/landmarks/ellipses")
    scans = sorted(seen.maps)
    assert sorted(points) == scans
    for k in scans:
        assert np.allclose(
            np.reshape(points[k], (-1, 2)), seen.maps[k][0], atol=1e-3
        )  # float32 in the recording
    expected, last = [], None
    for k in scans:
        joined_or_left = k == 0 or not np.array_equal(seen.maps[k][2], seen.maps[k - 1][2])
        if joined_or_left or seen.stamps[k] - seen.stamps[last] >= viz.ELLIPSES_EVERY_S:
            expected.append(k)
            last = k
    if expected[-1] != scans[-1]:
        expected.append(scans[-1])
    assert sorted(ellipses) == expected
    assert len(expected) < len(scans)  # the rule leaves scans out...
    assert any(  # ...and logs some because time passed, with the same landmarks
        np.array_equal(seen.maps[a][2], seen.maps[b][2])
        for a, b in zip(expected, expected[1:])
        if b != scans[-1]
    )


def test_the_map_at_the_last_scan_is_whole(recorded):
    """At the last scan the ellipses are logged whatever the rule says, one a landmark: those
    of the final map's covariances, drawn at the recording's scale."""
    path, seen = recorded
    last = max(seen.maps)
    xy, cov, ids = seen.maps[last]
    assert len(ids) >= 3
    strips = _entity_rows(path, "/world/landmarks/ellipses")[last]
    assert len(strips) == len(ids)
    want = ellipse_polylines(xy, cov * SCALE**2, n=viz.ELLIPSE_POINTS - 1)
    assert np.allclose(np.array(strips), want, atol=1e-3)


def test_the_docs_state_the_rule():
    from pathlib import Path

    page = " ".join((Path(__file__).parents[2] / "docs" / "rerun.md").read_text().split())
    assert f"once {viz.ELLIPSES_EVERY_S:g} s of the sequence's time" in page
    assert f"drawn with {viz.ELLIPSE_POINTS} points" in page
    sides = viz.ELLIPSE_POINTS - 1
    gap = 1 - np.cos(np.pi / sides)  # an inscribed polygon's largest gap to its ellipse
    assert f"{sides} sides, within {100 * gap:.1f}% of the ellipse" in page
    from experiments.bench.slam import RECORDING_PAIRS

    words = {1: "one", 2: "two", 3: "three", 4: "four", 5: "five"}
    assert f"{words[RECORDING_PAIRS]} such pairs (`bench.slam.RECORDING_PAIRS`" in page

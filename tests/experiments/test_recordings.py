"""Each kind of rerun recording, read back with the rerun SDK's reader: the entities, the
timelines and the blueprint (layout) it should carry."""

from __future__ import annotations

import numpy as np
import pytest
from support import read_recording, simulated_scan_file

from experiments.io.sequence_file import save_sequence
from experiments.paper.circles import pillar_monte_carlo
from experiments.pipeline.extract import run_extract
from experiments.pipeline.slam import run_slam_file
from experiments.render.viz import Recorder
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamConfig


def views_by_class(rec: dict, cls: str) -> list[tuple]:
    return [v for v in rec["views"] if v[0] == cls]


def assert_no_3d_view(rec: dict) -> None:
    assert rec["blueprints"] == 1
    assert not views_by_class(rec, "3D"), rec["views"]


@pytest.fixture(scope="module")
def slam_recording(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("slam_rec")
    seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=40))
    src = save_sequence(seq, tmp / "run.npz")
    cfg = SlamConfig().with_(**{"features.method": "geometric", "association.method": "ihgr"})
    run_slam_file(src, cfg, tmp / "out", rerun_path=tmp / "run.rrd")
    return read_recording(tmp / "run.rrd")


def test_slam_recording_entities(slam_recording):
    e = slam_recording["entities"]
    wanted = {
        "world/laser",  # the laser's pose; its children are in the laser frame
        "world/laser/scan",
        "world/laser/features/circles",
        "world/vehicle",
        "world/path",
        "world/follow",
        "world/landmarks",
        "world/landmarks/ellipses",
        "world/truth/trees",  # the simulated file's trees
        "world/truth/path",
        "series/pose_error/x",
        "series/pose_error/theta",
        "series/nis",
        "series/innovation/range",
        "series/map_size",
        "series/ms_per_scan",
    }
    assert wanted <= e, wanted - e


def test_slam_recording_has_scan_and_time_timelines(slam_recording):
    assert {"scan", "time"} <= slam_recording["timelines"]


def test_slam_recording_blueprint(slam_recording):
    assert_no_3d_view(slam_recording)
    origins = {v[1]: v for v in views_by_class(slam_recording, "2D")}
    # the map follows the vehicle and shows the whole world; the scan view is the laser frame
    assert origins["world/follow"][2] == ["/world/**"]
    assert "x10" in origins["world/follow"][3]  # the ellipse scale is said in the view
    assert origins["world/laser/y_up"][2] == ["/world/laser/**"]
    assert "world/y_up" in origins
    series = {v[1] for v in views_by_class(slam_recording, "TimeSeries")}
    assert {
        "series/pose_error/x",
        "series/pose_error/y",
        "series/pose_error/theta",
        "series/nis",
        "series/innovation/range",
        "series/innovation/bearing",
        "series/map_size",
        "series/ms_per_scan",
    } == series


def test_features_recording(tmp_path):
    src = simulated_scan_file(tmp_path)
    run_extract(src, tmp_path / "f.json", "geometric", rerun_path=tmp_path / "f.rrd")
    rec = read_recording(tmp_path / "f.rrd")
    wanted = {"laser/scan", "laser/features/segments", "laser/features/circles", "laser/y_up"}
    assert wanted | {"series/circles_per_scan"} <= rec["entities"]
    assert not any(e.startswith("world") for e in rec["entities"])
    assert {"scan", "time"} <= rec["timelines"]
    assert_no_3d_view(rec)
    assert [v[1] for v in views_by_class(rec, "2D")] == ["laser/y_up"]
    assert [v[1] for v in views_by_class(rec, "TimeSeries")] == ["series/circles_per_scan"]


def test_circles_recording(tmp_path):
    rec = Recorder(tmp_path / "c.rrd", "circles")
    mc = pillar_monte_carlo(1, np.random.default_rng(0), methods=("paper", "bailey"), rec=rec)
    rec.close()
    r = read_recording(tmp_path / "c.rrd")
    assert {
        "world/laser/scan",
        "world/circles/paper",
        "world/circles/bailey",
        "world/truth/pillars",
    } <= r["entities"]
    assert "scan" in r["timelines"]
    assert_no_3d_view(r)
    assert {v[1] for v in views_by_class(r, "2D")} == {"world/y_up", "figures/y_up"}
    assert len(mc.names) == 10


def test_recorder_refuses_unknown_kind_and_bad_scale(tmp_path):
    with pytest.raises(ValueError, match="kind"):
        Recorder(tmp_path / "x.rrd", "movie")
    with pytest.raises(ValueError, match="ellipse_scale"):
        Recorder(tmp_path / "x.rrd", "slam", ellipse_scale=0.0)


_MS_PER_SCAN = """
import json, numpy as np
from experiments.eval.series import slam_series
from experiments.sim import CycabParams, simulate_cycab_run
from slam import run_slam
seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=40))
lg = run_slam(seq, features="geometric", association="ihgr")
ms = next(s for s in slam_series(lg) if s.name == "ms_per_scan").values[:, 0]
print(json.dumps(ms.tolist()))
"""


@pytest.mark.slow
def test_time_per_scan_panel_has_no_first_scan_spike():
    """In a fresh process (numba kernels not yet loaded, lazy imports not yet done) the
    recording's ms-a-scan series of a small simulated run: the first scans are not outliers
    (below 10x the median, or no slower than the slowest later scan), so the panel's axis
    shows the run. Without `slam.run_slam`'s warm-up scan 0 takes seconds against a median of ms.

    Each scan's time is its fastest in 3 fresh processes: a scan takes about 0.5 ms, and when
    other work shares the cores (a parallel test run) the process loses a time slice, some
    5 ms, at a random scan (seen: scan 0 at 5.3 ms, the slowest later scan at 5.2 ms). A first
    scan slow by construction, what the warm-up prevents, is slow in every fresh process."""
    import json
    import subprocess
    import sys

    runs = []
    for _ in range(3):
        out = subprocess.run(
            [sys.executable, "-c", _MS_PER_SCAN], capture_output=True, text=True, check=True
        )
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    ms = np.min(np.array(runs), axis=0)
    assert ms.shape == (40,) and np.all(ms > 0)
    limit = max(10 * np.median(ms), ms[4:].max())
    assert np.all(ms[:4] <= limit), (ms[:4], np.median(ms), ms[4:].max())


def test_a_loop_closure_is_marked_on_the_timeline(tmp_path):
    """`log_closure` writes the match to the text log `events/closures` at its scan, even on
    a scan the decimation skips."""
    path = tmp_path / "c.rrd"
    with Recorder(path, kind="slam", decimate=10) as rec:
        rec.set_scan(7, 1.4)
        rec.log_closure(
            {
                "outcome": "accepted",
                "best": 9,
                "second": 3,
                "shift_m": 2.5,
                "rotation_deg": 1.0,
                "nis": 12.0,
                "nis_bound": 37.7,
                "merged": [(1, 40), (2, 41)],
            }
        )
    assert "events/closures" in read_recording(path)["entities"]


def test_a_duplicate_sweep_is_marked_on_the_timeline(tmp_path):
    """`log_duplicates` writes the sweep's merges to the same text log, even on a scan the
    decimation skips."""
    path = tmp_path / "d.rrd"
    with Recorder(path, kind="slam", decimate=10) as rec:
        rec.set_scan(7, 1.4)
        rec.log_duplicates([(2, 159)])
    assert "events/closures" in read_recording(path)["entities"]


def test_landmark_existence_colours_the_map_and_departures_are_marked(tmp_path):
    """Map policy "existence": `log_landmarks` takes each landmark's existence (its label and
    colour) and `log_departures` writes who left and why to the text log `events/map`."""
    path = tmp_path / "e.rrd"
    with Recorder(path, kind="slam", decimate=1) as rec:
        rec.set_scan(3, 0.6)
        rec.log_landmarks(np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1)), [4, 5], [0.99, 0.2])
        rec.log_departures([(6, "existence", 0.004)])
    e = read_recording(path)["entities"]
    assert "events/map" in e and "world/landmarks" in e

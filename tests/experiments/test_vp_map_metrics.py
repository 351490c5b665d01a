"""Victoria Park (needs the shared data): the table's GOSPA against the 2002 reference trees,
and a run's graph read back by GTSAM's readG2o."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from graph_support import assert_same_graph

from experiments.eval.gospa import gospa
from experiments.eval.map_quality import reference_in_our_frame
from experiments.io.g2o import g2o_text, read_g2o
from experiments.io.victoria_park import load_ss2002_reference, load_victoria_park
from experiments.paper.victoria_park.real_run import head, reference_match, run_config
from slam import run_slam, se2
from slam.graph import graph_of_problem
from slam.smoother import problem_from_log

pytestmark = [pytest.mark.data, pytest.mark.slow]


@pytest.fixture(scope="module")
def vp_run(vp_dir):
    """The first 500 scans with the published detections and the preset (as the table)."""
    seq = head(load_victoria_park(vp_dir), 500)
    lg = run_slam(seq, run_config("detections", "ihgr"))
    return lg, load_ss2002_reference(vp_dir)


def test_victoria_park_gospa_is_the_judged_landmarks_against_the_aligned_trees(vp_run):
    lg, (ground, trees) = vp_run
    row = reference_match(lg, lg.laser_pose, ground, trees)
    n = min(ground.shape[0], lg.n_scans)
    ours = np.array([se2.compose(p, lg.laser_pose)[:2] for p in lg.pose[:n]])
    tw = reference_in_our_frame(ours, ground, trees)
    judged = lg.landmark_xy[lg.landmark_first_scan < n]
    for c in (1.0, 20.0):
        g = gospa(judged, tw, p=2, c=c, alpha=2)
        assert row[f"gospa_{c:g}m"] == g.distance
        assert row[f"gospa_{c:g}m_missed"] == c**2 / 2 * g.n_missed
    # 500 of the 2000 scans: over half the 145 trees are not yet seen, missed at either
    # cut-off; a larger cut-off pairs at least as many (a landmark 1-20 m from an unseen tree
    # is a pair at c = 20 m, a missed and a false one at c = 1 m); at c = 1 m a pair is a
    # landmark within 1 m of its tree, at most as many as precision counts
    g1, g20 = (gospa(judged, tw, p=2, c=c, alpha=2) for c in (1.0, 20.0))
    assert g1.n_missed >= g20.n_missed > trees.shape[0] / 2
    assert g20.assigned >= g1.assigned > 10
    assert g1.assigned <= round(row["precision_1m"] * judged.shape[0])


def test_readG2o_reads_a_victoria_park_graph_back(vp_run, tmp_path):
    lg, _ = vp_run
    graph, _ = graph_of_problem(problem_from_log(lg))
    path = tmp_path / "vp.g2o"
    path.write_text(g2o_text(graph))
    g, values = gtsam.readG2o(str(path), False)
    assert_same_graph(read_g2o(path).graph, g, values)
    assert g.size() == graph.n_factors > lg.n_scans

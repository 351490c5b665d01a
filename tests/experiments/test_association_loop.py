"""The association methods in the SLAM loop: the K = 3 IHGR window's golden figures on seeded
tree-park runs, and the metrics of `experiments.eval.mapping`."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from regenerate_golden import FILES, window_loop

from experiments.eval.mapping import duplicates_and_missed, false_pairings
from slam.log import CONFIRMED, NEW_TENTATIVE


@pytest.mark.slow
def test_window_in_the_loop_matches_golden_figures():
    """Landmarks exactly (the mean over 2 runs), false pairings and updates within 2 and 1%,
    duplicates and missed trees exactly, pose error within 5%. Regenerate with
    `python tests/regenerate_golden.py window_loop` after a deliberate change."""
    golden = json.loads(FILES["window_loop"].read_text())
    got = window_loop()
    for method in ("IHGR window K = 3", "IHGR (single scan)"):
        g, x = golden[method], got[method]
        assert x["landmarks"] == g["landmarks"], method
        assert abs(x["false_pairings"] - g["false_pairings"]) <= 2, method
        assert x["updates"] == pytest.approx(g["updates"], rel=0.01), method
        assert (x["duplicates"], x["missed_trees"]) == (g["duplicates"], g["missed_trees"])
        assert x["pose_error_m"] == pytest.approx(g["pose_error_m"], rel=0.05), method
    # the window maps the 8 trees once each, pairs nothing falsely, and its LPs stay integral
    w = got["IHGR window K = 3"]
    assert w["landmarks"] == 8 and w["duplicates"] == 0 and w["missed_trees"] == 0
    assert w["false_pairings"] == 0


def test_false_pairings_count_measurements_of_another_object():
    # landmark 7 was made from object 0 (scans 0-2), then scan 3 paired object 1 with it
    lg = SimpleNamespace(
        meas_scan=np.array([0, 1, 2, 3, 3]),
        meas_feature=np.array([0, 0, 0, 0, 1]),
        meas_status=np.array([NEW_TENTATIVE, NEW_TENTATIVE, CONFIRMED, 7, NEW_TENTATIVE]),
        meas_track=np.array([7, 7, 7, 7, -1]),
        landmark_id=np.array([7]),
        obs_scan=np.array([3]),
        obs_feature=np.array([0]),
        obs_landmark=np.array([7]),
    )
    objects = {(0, 0): 0, (1, 0): 0, (2, 0): 0, (3, 0): 1, (3, 1): 0}
    assert false_pairings(lg, lambda k, i: objects[(k, i)]) == (1, 1)
    objects[(3, 0)] = 0
    assert false_pairings(lg, lambda k, i: objects[(k, i)]) == (0, 1)


def test_duplicates_and_missed_trees():
    trees = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    lm = np.array([[0.3, 0.0], [-0.5, 0.4], [0.0, 0.9], [10.0, 1.5]])
    assert duplicates_and_missed(lm, trees) == (2, 2)
    assert duplicates_and_missed(lm, trees, seen=np.array([True, True, False])) == (2, 1)
    assert duplicates_and_missed(lm, trees, tol_m=2.0) == (2, 1)
    assert duplicates_and_missed(np.zeros((0, 2)), trees) == (0, 3)

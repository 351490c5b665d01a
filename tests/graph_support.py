"""Comparing a `slam.graph.PoseGraph2D` with the graph GTSAM's `readG2o` makes of a file
(tests/experiments/test_graph_files.py, test_vp_map_metrics.py)."""

from __future__ import annotations

import gtsam
import numpy as np

from slam import se2

L = gtsam.symbol_shorthand.L
# a text round trip at 17 significant digits is exact; GTSAM's noise models are rebuilt from
# the numbers (an information matrix factored, sigmas inverted): equal to rounding, 1e-9 relative
TOL = 1e-9


def _gtsam_factors(graph) -> dict:
    """{(kind, key1, key2): (measured numbers, information matrix)} of a GTSAM graph."""
    out = {}
    for i in range(graph.size()):
        f = graph.at(i)
        k = tuple(f.keys())
        R = f.noiseModel().R()
        if isinstance(f, gtsam.BetweenFactorPose2):
            m = f.measured()
            out[("odo", *k)] = (np.array([m.x(), m.y(), m.theta()]), R.T @ R)
        else:
            m = f.measured()
            out[("br", *k)] = (np.array([m.bearing().theta(), m.range()]), R.T @ R)
    return out


def _ours(g) -> dict:
    out = {}
    for i, j, d, info in zip(g.odo_from, g.odo_to, g.odo_delta, g.odo_info):
        out[("odo", int(i), int(j))] = (d, info)
    for i, j, b, r, s in zip(g.br_pose, g.br_landmark, g.br_bearing, g.br_range, g.br_sigma):
        out[("br", int(i), L(int(j)))] = (np.array([b, r]), np.diag(1.0 / s**2))
    return out


def assert_same_graph(ours, graph, values) -> None:
    """Our PoseGraph2D and GTSAM's (graph, values): same factors (count, keys, measurements,
    information to 1e-9 relative) and same values to 1e-9."""
    theirs, mine = _gtsam_factors(graph), _ours(ours)
    assert graph.size() == ours.n_factors == len(theirs) == len(mine)
    assert theirs.keys() == mine.keys()
    for key, (z, info) in mine.items():
        z2, info2 = theirs[key]
        dz = z - z2
        dz[-1 if key[0] == "odo" else 0] = se2.wrap_angle(dz[-1 if key[0] == "odo" else 0])
        assert np.abs(dz).max() <= TOL * max(1.0, np.abs(z).max()), key
        assert np.abs(info - info2).max() <= TOL * np.abs(info).max(), key
    assert values.size() == ours.pose_id.size + ours.landmark_id.size
    for i, p in zip(ours.pose_id, ours.pose):
        q = values.atPose2(int(i))
        d = np.array([q.x() - p[0], q.y() - p[1], se2.wrap_angle(q.theta() - p[2])])
        assert np.abs(d).max() <= TOL * max(1.0, np.abs(p).max()), i
    for i, xy in zip(ours.landmark_id, ours.landmark_xy):
        assert np.abs(values.atPoint2(L(int(i))) - xy).max() <= TOL * max(1.0, np.abs(xy).max())

"""The map managers' one contract (`slam.map_managers.MapManager`): the single-scan manager and
the K-scan window are interchangeable behind it, and `manage` returns its decisions without
changing the measurements it was given."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slam import SlamConfig
from slam.ekf import Filter, initial_state
from slam.log import CONFIRMED, NEW_TENTATIVE, OUT_OF_RANGE
from slam.map_managers import MapDecisions, MapManager, View, make_map_manager
from slam.sources import Measurements

LASER = np.zeros(3)


def _manager(method: str, confirm_scans: int = 1) -> MapManager:
    cfg = SlamConfig().with_(
        **{"association.method": method, "map_policy.confirm_scans": confirm_scans}
    )
    view = View(fov=(-math.pi / 2, math.pi / 2), max_range=50.0)

    def nearest(z, R, z_hat, H, P, gate_prob=0.99, **params):  # the single-scan associator
        return np.full(z.shape[0], -1, np.int64)

    return make_map_manager(LASER, view, cfg.association, cfg.map_policy, nearest)


def _scan(k: int) -> Measurements:
    z = np.array([[10.0, 0.1], [20.0, -0.3], [80.0, 0.0]])
    status = np.array([NEW_TENTATIVE, NEW_TENTATIVE, OUT_OF_RANGE])
    return Measurements(k, None, None, z, np.tile(np.diag([1e-2, 1e-4]), (3, 1, 1)), status)


@pytest.mark.parametrize("method", ["ihgr", "ihgr-window"])
def test_both_managers_keep_the_contract_and_leave_the_measurements_alone(method):
    """With nothing mapped and every new measurement confirmed at once (the window: in
    min(confirm_scans, K) = 1 scan), both managers map the two usable measurements in the
    first scan, say so in their decisions (status CONFIRMED, the joined ids, their tracks),
    keep the out-of-range one out, and leave `meas.status` as the measure step made it."""
    manager = _manager(method)
    assert isinstance(manager, MapManager)
    state = Filter(initial_state(np.zeros(3), np.eye(3) * 1e-4))
    meas = _scan(0)
    before = meas.status.copy()
    a = manager.associate(state, meas, np.eye(3) * 1e-6, None)
    decisions = manager.manage(state, meas, a, np.full(3, -1, np.int64))
    assert isinstance(decisions, MapDecisions)
    np.testing.assert_array_equal(meas.status, before)
    assert decisions.status.tolist() == [CONFIRMED, CONFIRMED, OUT_OF_RANGE]
    joined = [lid for lid, _ in decisions.joined]
    assert state.landmark_ids.tolist() == joined and len(joined) == 2
    assert decisions.track[:2].tolist() == joined and decisions.track[2] == -1
    assert decisions.n_pending == manager.n_pending == 0 and decisions.retracks == []
    np.testing.assert_allclose(state.landmarks_xy[0], [10 * math.cos(0.1), 10 * math.sin(0.1)])

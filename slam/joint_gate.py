"""`JointGate`: `association.joint_check` on a scan's association before the update
(`[association] joint_check`).

The scan's pairings with mapped landmarks (`ScanAssociation.to_map`) share the vehicle's pose:
their stacked innovation and its joint covariance H P H^T + R, the pose's correlations
included, come from the filter as its update would compute them (`Filter.innovation`), with
the measurements' covariance as measured (the gates' white model). The joint test uses the
individual gates' probability (`association.gate_prob`). A dropped measurement is no longer
paired and is marked ambiguous: it lies in that landmark's gate, inside the wider new-feature
gate, where the map managers ignore an unpaired measurement (status AMBIGUOUS) rather than
start a landmark. Pairings with tentatives are not tested (they update nothing). Off (the
default), the run loop holds a `NoJointGate`, which passes every association unchanged.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from association.joint import joint_check
from slam.ekf import Filter
from slam.map_managers import ScanAssociation
from slam.sources import Measurements

__all__ = ["JointGate", "NoJointGate", "make_joint_gate"]


class JointGate:
    """The joint test of each scan's pairings (module doc); `dropped` collects
    [scan, measurement, landmark id] of every pairing it dropped (`SlamLog.joint_dropped`)."""

    def __init__(self, gate_prob: float, laser: np.ndarray) -> None:
        self.gate_prob, self.laser = float(gate_prob), laser
        self.dropped: list[list[int]] = []

    def record(self) -> list[list[int]]:
        """`SlamLog.joint_dropped`: the pairings dropped, [scan, measurement, landmark id]."""
        return list(self.dropped)

    def __call__(self, state: Filter, meas: Measurements, a: ScanAssociation) -> ScanAssociation:
        """The association `a` of scan meas.k without the pairings the joint test drops."""
        to_map = a.to_map()
        if to_map.size < 2:  # one pairing alone is its individual gate's
            return a
        pos = a.lm_idx[a.assign[to_map]]
        nu, S = state.innovation(pos, meas.z[to_map], meas.R[to_map], self.laser)
        check = joint_check(nu, S, self.gate_prob)
        if not check.dropped:
            return a
        rows = to_map[list(check.dropped)]
        ids = state.landmark_ids[pos[list(check.dropped)]]
        self.dropped += [[int(meas.k), int(i), int(lid)] for i, lid in zip(rows, ids)]
        assign, ambiguous = a.assign.copy(), a.ambiguous.copy()
        assign[rows], ambiguous[rows] = -1, True
        return dataclasses.replace(a, assign=assign, ambiguous=ambiguous)


class NoJointGate:
    """`[association] joint_check` off: every association passes unchanged, and the run log
    has no record (`SlamLog.joint_dropped` None)."""

    def __call__(self, state: Filter, meas: Measurements, a: ScanAssociation) -> ScanAssociation:
        return a

    def record(self) -> None:
        return None


def make_joint_gate(on: bool, gate_prob: float, laser: np.ndarray) -> JointGate | NoJointGate:
    """The run's joint gate, chosen once: `JointGate` when `[association] joint_check` is on,
    else `NoJointGate`."""
    return JointGate(gate_prob, laser) if on else NoJointGate()

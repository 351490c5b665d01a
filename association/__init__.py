"""Data association: measurements and predictions in, assignments out. Knows no EKF.

- `associate(z, R, z_hat, H, P, method="ihgr" | "jcbb" | "nn", gate_prob=..., **params)`:
  one scan (gate_prob: the caller's, no default here); returns the map feature of each
  measurement or -1. `associate_detailed` adds the method's statistics.
- `SlidingWindowAssociator`: K-scan IHGR for a SLAM loop, one committed scan per call.
- `ihgr_round` / `solve_set_partition`: the LP relaxation + iterative heuristic greedy rounding
  core, for any set-partitioning problem (and `milp` for the exact reference).
- `CostModel`: P_D, clutter and birth densities behind the negative-log-likelihood costs.
- `gate_matrix`: the individual chi-square gate of every measurement-feature pair
  (`association.gating`, the one home of the gate's arithmetic).

Standalone: imports numpy, scipy and numba only.
"""

from association.api import METHODS, Association, associate, associate_detailed
from association.errors import AssociationError
from association.gating import gate_matrix
from association.inputs import wrap_angle
from association.rounding import RoundingResult, ihgr_round, solve_set_partition
from association.single import CostModel
from association.window import SlidingWindowAssociator, WindowDecision

__all__ = [
    "associate",
    "associate_detailed",
    "gate_matrix",
    "Association",
    "METHODS",
    "SlidingWindowAssociator",
    "WindowDecision",
    "ihgr_round",
    "solve_set_partition",
    "RoundingResult",
    "CostModel",
    "wrap_angle",
    "AssociationError",
]

"""`associate`: the one entry point used by SLAM and by the experiments."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from association.errors import AssociationError
from association.inputs import Prepared, prepare
from association.jcbb import DEFAULT_MAX_NODES, jcbb_assign
from association.nn import nn_assign
from association.rounding import ROUNDING_OPTIONS, check_rounding_options
from association.single import CostModel, ihgr_single

__all__ = ["Association", "associate", "associate_detailed", "check_params", "METHODS"]

METHODS = ("ihgr", "jcbb", "nn")
_COST_KEYS = tuple(f.name for f in fields(CostModel))
_ROUNDING_KEYS = ROUNDING_OPTIONS
_PARAMS = {"ihgr": _COST_KEYS + _ROUNDING_KEYS, "jcbb": ("max_nodes",), "nn": ()}


@dataclass(frozen=True, eq=False)
class Association:
    """The answer of `associate_detailed`.

    assignment: (m,) int64, the map feature of each measurement or -1 (new feature or clutter).
    method: "ihgr", "jcbb" or "nn".
    d2: (m,) individual Mahalanobis distance of each chosen pairing, NaN where unpaired.
    cost: the method's objective: ihgr the negative log-likelihood (see `CostModel`), jcbb the
        joint Mahalanobis distance, nn the sum of individual distances.
    gated_pairs: number of individually compatible (measurement, feature) pairs.
    lp_solves, fractional: ihgr only, LP solves and whether the first LP was fractional.
    nodes, budget_exhausted: jcbb only, interpretation-tree nodes expanded and whether the node
        budget ran out (the answer is then the best found so far).
    """

    assignment: np.ndarray
    method: str
    d2: np.ndarray
    cost: float
    gated_pairs: int
    lp_solves: int = 0
    fractional: bool = False
    nodes: int = 0
    budget_exhausted: bool = False


def _rounding_options(params: dict) -> dict:
    """The IHGR rounding options among `params`, checked (`check_rounding_options`)."""
    return check_rounding_options({k: params[k] for k in _ROUNDING_KEYS if k in params})


def associate_detailed(
    z, R, z_hat, H, P, method: str = "ihgr", *, gate_prob: float, validate: bool = True, **params
) -> Association:
    """`associate` with the method's statistics; see `associate` for the arguments."""
    _check_method(method, params)
    prep = prepare(z, R, z_hat, H, P, gate_prob=gate_prob, validate=validate)
    out, cost, extra = _solve(prep, method, gate_prob, params)
    d2 = np.full(prep.m, np.nan)
    if prep.pair_i.size:
        lookup = {(int(i), int(j)): k for k, (i, j) in enumerate(zip(prep.pair_i, prep.pair_j))}
        for i in np.flatnonzero(out >= 0):
            d2[i] = prep.d2[lookup[(int(i), int(out[i]))]]
    if method == "nn":
        cost = float(np.nansum(d2))
    return Association(out, method, d2, float(cost), int(prep.pair_i.size), **extra)


def _check_method(method: str, params: dict) -> None:
    """`method` is one of `METHODS` and `params` are its parameters."""
    if method not in METHODS:
        raise AssociationError(f"method: expected one of {METHODS}, got {method!r}")
    unknown = set(params) - set(_PARAMS[method])
    if unknown:
        allowed = ", ".join(_PARAMS[method]) or "none"
        raise AssociationError(
            f"{sorted(unknown)}: not parameters of method {method!r} (allowed: {allowed})"
        )


def check_params(method: str, params: dict) -> None:
    """The keyword parameters `params` of `associate(..., method=method, **params)` checked as
    the solve would take them, before any solve: names of the method, and values of the right
    type and range (the `CostModel`'s densities, the rounding options, jcbb's node budget);
    `AssociationError` naming the parameter otherwise."""
    if not isinstance(params, dict) or not all(isinstance(k, str) for k in params):
        raise AssociationError(f"params: expected a table of named parameters, got {params!r}")
    _check_method(method, params)
    if method == "ihgr":
        CostModel(**{k: params[k] for k in _COST_KEYS if k in params})
        _rounding_options(params)
    elif method == "jcbb" and "max_nodes" in params:
        n = params["max_nodes"]
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= 2**31:
            raise AssociationError(f"max_nodes: must be a whole number in 1..2**31, got {n!r}")


def _solve(prep: Prepared, method: str, gate_prob: float, params: dict):
    """(assignment, cost (NaN for nn), statistics) of `associate_detailed` on prepared inputs;
    `method` and `params` checked (`_check_method`)."""
    extra: dict = {}
    if method == "ihgr":
        model = CostModel(**{k: params[k] for k in _COST_KEYS if k in params})
        rounding = _rounding_options(params)
        out, res = ihgr_single(prep, model, **rounding)
        cost = res.cost
        extra = {"lp_solves": res.lp_solves, "fractional": res.fractional}
    elif method == "jcbb":
        out, stats = jcbb_assign(prep, float(gate_prob), params.get("max_nodes", DEFAULT_MAX_NODES))
        cost = stats.joint_d2
        extra = {"nodes": stats.nodes, "budget_exhausted": stats.budget_exhausted}
    else:
        out = nn_assign(prep)
        cost = math.nan
    return out, cost, extra


def associate(
    z, R, z_hat, H, P, method: str = "ihgr", *, gate_prob: float, validate: bool = True, **params
) -> np.ndarray:
    """Associate the m measurements of one scan with the n map features.

    z: (m, 2) measurements [range_m, bearing_rad].
    R: (2, 2) or (m, 2, 2) measurement noise covariance(s), symmetric positive definite.
    z_hat: (n, 2) predicted measurements [range_m, bearing_rad] of the map features.
    H: (n, 2, d) Jacobian of each prediction with respect to the d-dimensional state.
    P: (d, d) state covariance, symmetric positive semi-definite.
    method: "ihgr" (LP + iterative heuristic greedy rounding, costs of `CostModel`),
        "jcbb" (joint compatibility branch and bound) or "nn" (gated nearest neighbour).
    gate_prob: probability of the chi-square gates (individual: 2 dof; JCBB joint: 2k dof).
        No default here: the caller's setting is the one (`slam.config.AssociationConfig`'s
        0.999 for a SLAM run; the association study's own 0.99).
    validate: False skips the checks of z, R, z_hat, H, P and gate_prob (shapes, finite,
        symmetric, positive (semi-)definite; `association.inputs.prepare`), for callers whose
        inputs are valid by construction, such as the SLAM loop: the same answer for valid
        input, undefined for invalid input. The method and its parameters are still checked.
    params: ihgr: p_detect, clutter_density, birth_density (`CostModel`), and the rounding
        options eps, fix_ones, presolve (`ihgr_round`); jcbb: max_nodes (node budget).

    Returns (m,) int64: for each measurement the index of its map feature in 0..n-1, or -1 for
    a new feature or clutter. Every feature is used at most once. Bearing differences are
    wrapped to (-pi, pi]. Raises AssociationError (a ValueError) naming the argument for
    malformed input (shapes, NaN or inf, negative ranges, R not positive definite, P not
    symmetric positive semi-definite on the blocks used).
    """
    _check_method(method, params)
    prep = prepare(z, R, z_hat, H, P, gate_prob=gate_prob, validate=validate)
    # without `associate_detailed`'s per-pair distances and cost, which it does not return
    return _solve(prep, method, gate_prob, params)[0]

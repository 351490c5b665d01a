"""Scores that cannot be computed: null in a summary, and said so.

A run can be too short, or its GPS too late, for a figure to exist: the RMSE over no fix, the
alignment of two fixes, the NEES of a scan whose covariance is singular. Such a figure is NaN
in the computation; in `summary.json` and `smoother.json` it is `null`, and the summary's
`not_computed` lists every one of them with the reason, so that a run never dies writing its
summary after the work, and nobody reads a missing figure as a zero.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["null_scores"]


def null_scores(summary: dict, scores=("gps", "truth"), reasons: dict | None = None) -> dict:
    """`summary` with every non-finite number (NaN, inf: a figure that could not be computed)
    replaced by None, and `not_computed` = {dotted key: why} listing those, and the figures of
    the `scores` sections that are None already (elsewhere None is a setting left unset).
    reasons: why, by dotted key ("gps.vouched_rmse": ...) or, failing that, by top-level key
    ("gps": "no fix within the run"); others get a general reason."""
    reasons = reasons or {}
    found: dict[str, str] = {}

    def walk(v, path: str):
        if isinstance(v, dict):
            return {k: walk(x, f"{path}.{k}" if path else str(k)) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [walk(x, f"{path}[{i}]") for i, x in enumerate(v)]
        if isinstance(v, (np.floating, np.integer)):
            v = v.item()
        top = path.split(".", 1)[0].split("[", 1)[0]
        if (v is None and top in scores) or (isinstance(v, float) and not math.isfinite(v)):
            found[path] = reasons.get(path, reasons.get(top, "too few values to compute it from"))
            return None
        return v

    out = walk({k: v for k, v in summary.items() if k != "not_computed"}, "")
    if found:
        out["not_computed"] = found
    return out

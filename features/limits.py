"""The range of the extractors' numeric parameters: the range where their maths holds.

Every parameter that reaches a kernel is a finite number whose size is 0 or within
[PARAM_TINY, PARAM_LIMIT]: its square is then a normal double (no variance or gate computed
from it underflows to 0 or to a subnormal, and subnormal inputs are refused), and its square,
or a product of a few such squares, stays far from overflow (int64 counts too).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import field

__all__ = ["PARAM_LIMIT", "PARAM_TINY", "in_range", "is_real", "magnitude_problem", "sourced"]

PARAM_LIMIT = 1e9  # no extractor parameter is larger in size (metres, counts, thresholds)
PARAM_TINY = 1e-150  # nor smaller, 0 apart: (1e-150)^2 > 2.2e-308, the least normal double


def is_real(v) -> bool:
    """Whether `v` is a finite real number (bools are not numbers here)."""
    return not isinstance(v, bool) and isinstance(v, numbers.Real) and math.isfinite(v)


def in_range(v, limit: float = PARAM_LIMIT) -> bool:
    """Whether the real number `v` has a size of 0 or within [PARAM_TINY, limit]: the project's
    one range check of a number that reaches a kernel (its square neither underflows nor
    overflows); `magnitude_problem` and `slam.validators.setting` both use it."""
    return abs(v) <= limit and (v == 0 or abs(v) >= PARAM_TINY)


def magnitude_problem(v, positive: bool = False, *, limit: float = PARAM_LIMIT) -> str | None:
    """What is wrong with `v` as a parameter's value (None: nothing): not a finite real number,
    or a size outside {0} and [PARAM_TINY, limit] (`in_range`). positive: the parameter must be
    > 0 (the message then leaves 0 out; the caller refuses 0 and negative values)."""
    if not is_real(v):
        return f"must be a finite number, got {v!r}"
    if in_range(v, limit):
        return None
    if abs(v) > limit:  # squares and int64 kernels must not overflow
        return f"must be at most {limit:g} in size, got {v!r}"
    least = "" if positive else "0 or "  # its square would underflow
    return f"must be {least}at least {PARAM_TINY:g} in size, got {v!r}"


def sourced(value, source: str):
    """A parameter's default with where it comes from, in one line ("paper: ...", "design: ...",
    ...), as `slam.config.default` does for the run's settings (`slam.config.setting_sources`
    lists both)."""
    return field(default=value, metadata={"source": source})

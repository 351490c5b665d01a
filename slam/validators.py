"""Leaf validators: the input checks shared by the run's data types (`Sequence`, `Odometry`)
and settings, one place for each rule, each taking the qualified name of what it checks (e.g.
"Sequence.scan_t"). Errors are `SlamError` (a `ValueError`) naming the field and what to change.

This module imports nothing of `slam` but its errors, so every module may use it; the checks a
run makes before it starts (they need the configuration and the sequence) are `slam.checks`.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from features.limits import PARAM_TINY, in_range, is_real
from slam.errors import SlamError

__all__ = [
    "SETTING_TINY",
    "SIGMA_LIMIT",
    "finite",
    "float_array",
    "nonnegative_fields",
    "readonly",
    "setting",
    "times",
]

# The range where the kernels' maths holds for a setting that feeds them (noise sigmas, floors,
# poses, calibrations): a finite number whose size is 0 or within [SETTING_TINY, its limit].
# Above the limit its square leaves the sequence file's range for variances (its squares and
# their products overflow long before 1e300); below SETTING_TINY its square underflows to a
# subnormal or 0 (a covariance that is singular by rounding). Subnormals are refused.
SETTING_TINY = PARAM_TINY  # (1e-150)^2 > 2.2e-308, the least normal double
SIGMA_LIMIT = 1e8  # m, rad, m/s, ...: sqrt(slam.sequence.MAX_VARIANCE), the file's largest sigma


def setting(path: str, v, *, signed: bool = False, limit: float = SIGMA_LIMIT) -> None:
    """`v` a setting that feeds a kernel: a real number whose size is 0 or within
    [SETTING_TINY, limit] (`features.limits.in_range`, the one range check of the project's
    settings and parameters), and >= 0 unless `signed`; a `SlamError` naming `path` and the
    allowed range otherwise."""
    if not isinstance(v, (int, float)) or not is_real(v):  # a Python number, as a file gives
        raise SlamError(f"{path}: must be a finite number, got {v!r}")
    if not signed and v < 0:
        raise SlamError(f"{path}: must be a finite number >= 0, got {v!r}")
    if not in_range(v, limit):
        size = "of size " if signed else ""
        raise SlamError(
            f"{path}: must be 0 or a number {size}in [{SETTING_TINY:g}, {limit:g}], got {v!r}"
        )


def nonnegative_fields(owner: str, obj) -> None:
    """Every field of the dataclass `obj` a finite real number >= 0 (noise sigmas) in the range
    of `setting`; a `SlamError` naming `owner`.field otherwise."""
    for f in fields(obj):
        setting(f"{owner}.{f.name}", getattr(obj, f.name))


def readonly(a: np.ndarray) -> np.ndarray:
    """`a`, made read-only (returned for chaining)."""
    a.setflags(write=False)
    return a


def float_array(name: str, value, ndim: int, width: int | None = None) -> np.ndarray:
    """A read-only float64 copy of `value` with `ndim` dimensions (and `width` columns)."""
    try:
        a = np.array(value)
    except Exception as exc:  # ragged lists and the like
        raise SlamError(f"{name}: cannot be read as an array ({exc})") from None
    if a.dtype.kind not in "fiu":
        raise SlamError(f"{name}: expected numbers, got dtype {a.dtype}")
    expected = {1: "(n,)", 2: f"(n, {width})" if width else "(n, m)"}.get(ndim, f"{ndim}-D")
    if a.ndim != ndim or (width is not None and a.shape[-1] != width):
        raise SlamError(f"{name}: expected shape {expected}, got {a.shape}")
    return readonly(a.astype(np.float64))


def finite(name: str, a: np.ndarray) -> None:
    """Raise unless every value of `a` is finite."""
    if not np.all(np.isfinite(a)):
        raise SlamError(f"{name}: values must be finite (NaN or inf found)")


def times(name: str, value) -> np.ndarray:
    """`value` as read-only float64 times (n,), checked finite and strictly increasing."""
    t = float_array(name, value, 1)
    if not np.all(np.isfinite(t)):
        raise SlamError(
            f"{name}: times must be finite (first bad index "
            f"{int(np.flatnonzero(~np.isfinite(t))[0])})"
        )
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0])
        short = name.rsplit(".", 1)[-1]
        raise SlamError(
            f"{name}: times must be strictly increasing; {short}[{i + 1}] = "
            f"{t[i + 1]!r} s follows {short}[{i}] = {t[i]!r} s ({bad.size} such step(s))"
        )
    return t

"""Input checks shared by the run's data types (`Sequence`, `Odometry`): one place for each rule.

Each function takes the qualified name of what it checks (e.g. "Sequence.scan_t") and raises
`SlamError` (a `ValueError`) naming it.
"""

from __future__ import annotations

import numpy as np

from slam.errors import SlamError

__all__ = ["float_array", "finite", "readonly", "times"]


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

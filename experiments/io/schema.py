"""A small declarative schema for the JSON formats we read (the features JSON), checked before
any number is used: a wrong type anywhere is a `DataError` naming the file and the key path
(`scans[3].circles[0].cov[1][2]: expected a number or null, got "x"`).

Why not pydantic: it is not a dependency, and the formats are small and fixed; what they need
(a path in every message, null for a non-finite number, limits in the format's units, huge
integers and NaN tokens refused by name) is a few dozen lines here, whereas pydantic's messages
and coercions (a "1.5" string taken for a number unless strict mode) would need the same amount
of code to shape. The TOML formats have their schema in their dataclasses
(`slam.config.config_from_dict`), the `.npz` formats in `experiments.io.npz`.

    Number(nullable=False, low=-inf, high=inf, integer=False)
    String(nonempty=True, choices=None)
    ListOf(item, length=None)
    Table(required={...}, optional={...})   # a JSON object with exactly these keys
    AnyTable()                              # a JSON object of anything (free-form settings)

`parse_json(text, source)` reads JSON with integers too long for a float read as inf and the
non-standard NaN/Infinity tokens kept as markers that `Number` refuses by name.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping

from experiments.errors import DataError

__all__ = ["AnyTable", "ListOf", "Number", "String", "Table", "check", "parse_json"]


class NotJson(str):
    """A non-standard JSON token (NaN, Infinity, -Infinity), kept to be refused by name."""


def _int(text: str) -> int | float:
    """An integer too long for a float is read as inf (refused as not finite), not as a
    400-digit int that overflows later."""
    return int(text) if len(text) < 300 else float(text)


def parse_json(text: str, source: str, what: str):
    """The JSON value of `text`; `DataError` naming `source` when it is not JSON."""
    try:
        return json.loads(text, parse_int=_int, parse_constant=NotJson)
    except json.JSONDecodeError as exc:
        raise DataError(f"{source}: not a {what} (not valid JSON: {exc})") from None
    except RecursionError:
        raise DataError(f"{source}: JSON nested too deeply to be a {what}") from None


def _shown(v) -> str:
    if isinstance(v, (dict, list)):
        return "a table" if isinstance(v, dict) else f"a list of {len(v)}"
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


class Number:
    """A JSON number: finite (null allowed when `nullable`, read as NaN), within [low, high];
    `integer`: a whole number (a JSON integer)."""

    def __init__(self, *, nullable=False, low=-math.inf, high=math.inf, integer=False):
        self.nullable, self.low, self.high, self.integer = nullable, low, high, integer

    def check(self, v, where: str):
        if v is None and self.nullable:
            return math.nan
        if isinstance(v, NotJson):
            raise ValueError(
                f"{where}: {v} is not valid JSON (a value that is not finite is written as null)"
            )
        want = "an integer" if self.integer else "a number" + (" or null" if self.nullable else "")
        ok_type = isinstance(v, int) if self.integer else isinstance(v, (int, float))
        if isinstance(v, bool) or not ok_type:
            raise ValueError(f"{where}: expected {want}, got {_shown(v)}")
        if not math.isfinite(v):
            raise ValueError(f"{where}: expected {want}, got a number too large ({v})")
        if not self.low <= v <= self.high:
            raise ValueError(f"{where}: must be in [{self.low:g}, {self.high:g}], got {v!r}")
        return v


class String:
    """A JSON string (non-empty unless told), one of `choices` when given."""

    def __init__(self, *, nonempty=True, choices=None):
        self.nonempty, self.choices = nonempty, choices

    def check(self, v, where: str):
        if not isinstance(v, str) or isinstance(v, NotJson):
            raise ValueError(f"{where}: expected a string, got {_shown(v)}")
        if self.nonempty and not v.strip():
            raise ValueError(f"{where}: expected a non-empty string")
        if self.choices is not None and v not in self.choices:
            raise ValueError(f"{where}: expected one of {list(self.choices)}, got {_shown(v)}")
        return v


class ListOf:
    """A JSON list of `item`s (exactly `length` of them when given)."""

    def __init__(self, item, length: int | None = None):
        self.item, self.length = item, length

    def check(self, v, where: str):
        if not isinstance(v, list):
            n = f"{self.length} " if self.length is not None else ""
            raise ValueError(f"{where}: expected a list of {n}items, got {_shown(v)}")
        if self.length is not None and len(v) != self.length:
            raise ValueError(f"{where}: expected {self.length} items, got {len(v)}")
        return [self.item.check(x, f"{where}[{i}]") for i, x in enumerate(v)]


class Table:
    """A JSON object with the `required` keys, and of the `optional` ones any; no other key."""

    def __init__(self, required: Mapping, optional: Mapping | None = None):
        self.required, self.optional = dict(required), dict(optional or {})

    def check(self, v, where: str):
        if not isinstance(v, dict):
            raise ValueError(f"{where or 'top level'}: expected a JSON object, got {_shown(v)}")
        known = {**self.required, **self.optional}
        for k in v:
            if k not in known:
                raise ValueError(
                    f"{_join(where, k)}: unknown key (known here: {', '.join(sorted(known))})"
                )
        missing = [k for k in self.required if k not in v]
        if missing:
            raise ValueError(
                f"{where or 'top level'}: needs {', '.join(self.required)}; missing "
                f"{', '.join(missing)}"
            )
        return {k: known[k].check(x, _join(where, k)) for k, x in v.items()}


class AnyTable:
    """A JSON object of anything (settings kept for the record)."""

    def check(self, v, where: str):
        if not isinstance(v, dict):
            raise ValueError(f"{where}: expected a JSON object, got {_shown(v)}")
        return v


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def check(schema, value, source: str):
    """`value` checked against `schema`; `DataError` "<source>: <key path>: ..." when not."""
    try:
        return schema.check(value, "")
    except ValueError as exc:
        raise DataError(f"{source}: {exc}") from None

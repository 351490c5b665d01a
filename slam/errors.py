"""The error `slam` raises for bad input (a `ValueError`, as the API promises)."""

from __future__ import annotations

__all__ = ["SlamError"]


class SlamError(ValueError):
    """A run, configuration or state that cannot be used: the message names the field."""

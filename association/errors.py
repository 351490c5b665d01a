"""The error `association` raises for bad input (a `ValueError`, as the API promises)."""

from __future__ import annotations

__all__ = ["AssociationError"]


class AssociationError(ValueError):
    """Bad input to an associator: the message names the argument."""

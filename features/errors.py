"""The error `features` raises for bad input (a `ValueError`, as the API promises)."""

from __future__ import annotations

__all__ = ["FeaturesError"]


class FeaturesError(ValueError):
    """Bad input to the feature extractor: the message names the parameter or field."""

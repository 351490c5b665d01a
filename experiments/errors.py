"""The project's own error types, mapped to a message and exit code 1 by the CLI."""

from __future__ import annotations


class TrunkslamError(Exception):
    """Base of trunkslam's own errors."""


class DataError(TrunkslamError, ValueError):
    """A data file or in-memory run is missing, corrupt or inconsistent; the message says what."""


class ConfigError(TrunkslamError, ValueError):
    """A parameter, option or configuration value that cannot be used; the message names it."""

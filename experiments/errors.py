"""The project's own error types, mapped to a message and exit code 1 by the CLI."""

from __future__ import annotations


class TrunkslamError(Exception):
    """Base of trunkslam's own errors."""


class DataError(TrunkslamError, ValueError):
    """A data file or in-memory run is missing, corrupt or inconsistent; the message says what."""


class ConfigError(TrunkslamError, ValueError):
    """A parameter, option or configuration value that cannot be used; the message names it."""


class MissingDataError(DataError):
    """A dataset that is not there at all (no folder, a file missing): experiments that need it
    are skipped with a note. A file that is there but corrupt is a plain `DataError`."""


class WriteError(OSError):
    """An output that could not be written (a full disk, a file-size limit, a lost permission):
    "cannot write PATH: REASON", naming the output as the user gave it. An OSError, not a
    `TrunkslamError`: `trunkslam reproduce` stops the whole run on it, as on any write error,
    rather than failing one experiment."""

    def __init__(self, path, exc: OSError) -> None:
        super().__init__(exc.errno, exc.strerror or str(exc), str(path))

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"


class ExperimentFailed(TrunkslamError):
    """One or more experiments of a `trunkslam reproduce` run failed; the message names them."""


def input_errors() -> tuple[type[BaseException], ...]:
    """The exception types that mean bad input (files, data, parameters), not a bug: the
    project's own errors of every package, and OSError. A package's error is taken only once
    the package is loaded (none of its errors can have been raised before): importing
    `slam.errors` would load all of `slam` (numpy, numba, scipy), and a refused input or
    `--help` would pay for it."""
    import sys

    out: list[type[BaseException]] = [TrunkslamError]
    for module, name in (
        ("features.errors", "FeaturesError"),
        ("association.errors", "AssociationError"),
        ("slam.errors", "SlamError"),
    ):
        if module in sys.modules:
            out.append(getattr(sys.modules[module], name))
    return (*out, OSError)

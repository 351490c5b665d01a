"""Each warning once per process: a logging filter for the command line and the workers.

A trial that meets the same condition as the trial before it (a setting, a skipped data set)
logs the same warning again; over a Monte Carlo study that is the same line a hundred times.
`OnceFilter` lets the first of each distinct warning through and drops its repeats; records
below WARNING (the `-v` detail) all pass.
"""

from __future__ import annotations

import logging

__all__ = ["OnceFilter", "warn_once_per_process"]


class OnceFilter(logging.Filter):
    """Passes a WARNING-or-worse record only the first time its (level, message) is seen."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[tuple[int, str]] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        key = (record.levelno, record.getMessage())
        if key in self.seen:
            return False
        self.seen.add(key)
        return True


def warn_once_per_process() -> None:
    """In a worker process: warnings to stderr as the command line shows them, each once."""
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
    handler.addFilter(OnceFilter())
    logging.basicConfig(level=logging.WARNING, handlers=[handler])

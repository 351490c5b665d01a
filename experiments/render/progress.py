"""Progress of long loops on stderr: redrawn in place on a terminal, a line a quarter otherwise."""

from __future__ import annotations

import sys

__all__ = ["Progress"]


class Progress:
    """A callable progress(description, done, total) for `RunContext.progress` and the like."""

    def __init__(self) -> None:
        self.last = ""
        self.tty = sys.stderr.isatty()

    def __call__(self, desc: str, done: int, total: int) -> None:
        width = 30
        frac = done / max(total, 1)
        if not self.tty:
            step = f"{desc} {int(4 * frac) * 25}%"
            if step != self.last:
                sys.stderr.write(f"{desc}: {done}/{total}\n")
                self.last = step
            return
        filled = int(width * frac)
        line = f"\r{desc:<28} [{'#' * filled}{'.' * (width - filled)}] {done}/{total}"
        if line != self.last:
            sys.stderr.write(line + ("\n" if done >= total else ""))
            sys.stderr.flush()
            self.last = line

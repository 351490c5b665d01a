"""`open_recording` for the commands: rerun (and the pandas and pyarrow it loads, about a
second of CPU per process) is imported only when a run records, so that `trunkslam slam` or
`extract` without `--rerun` does not load it."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from experiments.render.null_recorder import NullRecorder

if TYPE_CHECKING:
    from experiments.render.rerun_sink import Viewer


def open_recording(
    target: Path | str | Viewer | None, kind: str = "slam", **settings
) -> NullRecorder:
    """`experiments.render.viz.open_recording(target, kind, **settings)`: a NullRecorder when
    target is None, without importing rerun."""
    if target is None:
        return NullRecorder()
    from experiments.render.viz import open_recording as recording

    return recording(target, kind, **settings)

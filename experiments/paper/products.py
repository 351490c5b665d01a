"""Figures and recordings made as trials on the executor, their files written by this process.

A product is an output file made on a worker beside other experiments' trials instead of in the
main process, which would keep the workers waiting. The trial returns the file's bytes as its
record, {file name: bytes}: a Dask worker may be another machine, so a worker never writes into
the result folder; `write` puts the bytes there atomically. Products are drawn from what the
experiment computed (`figures`), or made by a trial of the experiment's own (a recording: see
`experiments.render.viz.MemoryRecorder`). Either way they depend only on their arguments, so the
files are the same whatever ran them: PNG byte for byte; a recording up to the ids and
timestamps rerun puts in every file.

- `figure_trial`: draws one figure (a `plot_*` function of `experiments.render.plots`)
- `figures(ctx, specs)`: draws figures on the executor and writes them after the experiments
  (`RunContext.later`)
- `write(ctx, files)`: writes a product's files into the result folder
"""

from __future__ import annotations

import io
from collections.abc import Callable

from experiments.io.writers import write_atomic

__all__ = ["FigureSpec", "figure_trial", "figures", "png", "write"]

# (file name, a plot_* function of experiments.render.plots, its arguments before `path`, its
# keyword arguments): the figure `plot(*args, path=..., **kwargs)` draws
FigureSpec = tuple[str, Callable, tuple, dict]


def png(plot: Callable, *args, **kwargs) -> bytes:
    """The PNG file `plot(*args, path=..., **kwargs)` writes, as bytes."""
    buf = io.BytesIO()
    plot(*args, path=buf, **kwargs)
    return buf.getvalue()


def figure_trial(spec: FigureSpec, seed=None) -> dict[str, bytes]:
    """One figure drawn wherever the executor runs it: {file name: PNG bytes}. Deterministic
    (the seed is unused)."""
    name, plot, args, kwargs = spec
    return {name: png(plot, *args, **kwargs)}


def write(ctx, files: dict[str, bytes]) -> None:
    """Write the files of a product into the result folder (atomically, each)."""
    for name, data in files.items():
        ctx.outputs.append(write_atomic(ctx.path(name), data))


def figures(ctx, specs: list[FigureSpec], desc: str = "figures") -> None:
    """Draw figures on the executor, one trial each, beside the next experiments' trials; their
    files are written once every experiment has started (`RunContext.later`)."""
    if not specs:
        return
    batch = ctx.submit(figure_trial, specs, desc=desc, chunksize=1)

    def finish(records: list[dict[str, bytes]]) -> None:
        for files in records:
            write(ctx, files)

    ctx.later(batch, finish)

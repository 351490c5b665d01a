"""What an experiment writes, declared: its tables (`TableSpec`), figures (`FigureSpec`) and
recordings; an experiment computes its results (the study) and a report step writes these from
them (`tables`, `figures`).

A table is declared once, beside the experiment: its file stem, how its tidy records come from
the study's results, and how its Markdown pivots them (`experiments.io.writers.tidy_table`).

Figures and recordings are made as trials on the executor, their files written by this process.

A product is an output file made on a worker beside other experiments' trials instead of in the
main process, which would keep the workers waiting. The trial returns the file's bytes as its
record, {file name: bytes}: a Dask worker may be another machine, so a worker never writes into
the result folder; `write` puts the bytes there atomically. Products are drawn from what the
experiment computed (`figures`), or made by a trial of the experiment's own (a recording: see
`experiments.render.viz.MemoryRecorder`). Either way they depend only on their arguments, so the
files are the same whatever ran them: PNG byte for byte; a recording up to the ids and
timestamps rerun puts in every file.

- `figure_trial`: draws one figure (a `plot_*` function of an experiment's figure module)
- `figures(ctx, specs)`: draws figures on the executor and writes them after the experiments
  (`RunContext.later`)
- `write(ctx, files)`: writes a product's files into the result folder
- `tables(ctx, specs, results)`: writes tables from the study's results (in this process: a
  table is cheap)
"""

from __future__ import annotations

import io
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from experiments.io.writers import tidy_table, write_atomic

__all__ = ["FigureSpec", "TableSpec", "figure_trial", "figures", "png", "tables", "write"]

# (file name, a plot_* function of a figure module, its arguments before `path`, its
# keyword arguments): the figure `plot(*args, path=..., **kwargs)` draws
FigureSpec = tuple[str, Callable, tuple, dict]


@dataclass(frozen=True)
class TableSpec:
    """One result table, declared: its files, how its records come from the study's results,
    and how its Markdown shows them. `write` makes stem.csv (the records, one row each) and
    stem.md (their pivot; `experiments.io.writers.write_tidy_table` says how).

    stem: the file name without its suffix.
    records: results -> the tidy records (dicts, one per observation).
    index, columns: the fields whose values make the Markdown's rows and columns.
    values: the field(s) its cells show; None: every field not in index or columns, in order
        of first appearance (a table with one record per row).
    parts: ((heading, value names), ...): the Markdown as narrow tables, one per part.
    labels: headers (a field's name, or a column key as text or tuple -> its header).
    title, notes: the Markdown's heading, and the text under the table.
    labels, title and notes are given as they are, or as functions of the results (a note
    that quotes a figure of the study).
    """

    stem: str
    records: Callable[[Any], list[dict]]
    index: tuple[str, ...]
    columns: tuple[str, ...] = ()
    values: str | tuple[str, ...] | None = "value"
    parts: tuple[tuple[str, tuple[str, ...]], ...] = ()
    labels: Mapping | Callable[[Any], Mapping] = field(default_factory=dict)
    title: str | Callable[[Any], str] = ""
    notes: str | Callable[[Any], str] = ""

    def texts(self, results) -> tuple[str, str]:
        """(Markdown, CSV) of the table of `results`."""
        records = self.records(results)
        values = self.values
        if values is None:
            keys = {*self.index, *self.columns}
            values = tuple(k for k in dict.fromkeys(k for r in records for k in r) if k not in keys)
        return tidy_table(
            self.stem,
            records,
            self.index,
            self.columns,
            values,
            labels=dict(_given(self.labels, results)),
            title=_given(self.title, results),
            notes=_given(self.notes, results),
            parts=self.parts,
        )

    def write(self, out_dir: Path | str, results) -> list[Path]:
        """Write stem.md and stem.csv of `results` into `out_dir` (atomically); their paths."""
        md, text = self.texts(results)
        stem = Path(out_dir) / self.stem
        return [
            write_atomic(stem.with_suffix(".md"), md),
            write_atomic(stem.with_suffix(".csv"), text),
        ]


def _given(value, results):
    """A TableSpec text or mapping: as given, or made from the results."""
    return value(results) if callable(value) else value


def tables(ctx, specs, results) -> None:
    """The report step of the tables: write every table of `specs` from the study's `results`
    into the result folder."""
    for spec in specs:
        ctx.outputs += spec.write(ctx.out_dir, results)


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

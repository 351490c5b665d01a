"""Commands that run experiments and refresh the documentation: reproduce, sweep, report."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Annotated

import typer

from experiments.cli.base import MAX_WORKERS, app, dask_address, handle_errors
from experiments.cli.choices import ExperimentName, Study
from experiments.paper.registry import help_lines  # light: reads the declarations


@app.command()
@handle_errors
def reproduce(
    names: Annotated[
        list[ExperimentName] | None,
        typer.Argument(
            help="experiments to run (default: all but the two victoria-park-* calibrations)"
        ),
    ] = None,
    quick: Annotated[bool, typer.Option(help="small-sample version")] = False,
    out: Annotated[Path, typer.Option(help="output folder")] = Path("results"),
    seed: Annotated[int, typer.Option(help="root random seed", min=0)] = 0,
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=MAX_WORKERS,
            help="local worker processes for the trials (1: this process; at most 4096) "
            "[default: every core]",
        ),
    ] = None,
    dask: Annotated[
        str | None,
        typer.Option(
            envvar="TRUNKSLAM_DASK",
            callback=dask_address,
            help="run the trials on this Dask scheduler (tcp://host:8786) instead of local "
            "processes; needs trunkslam[dask] [default: $TRUNKSLAM_DASK, else none]",
        ),
    ] = None,
) -> None:
    """Run the paper's experiments: tables (.md/.csv), figures (.png), recordings (.rrd).

    The trials run on every local core (--workers), or on a Dask cluster (--dask); the numbers
    are the same whichever, bit for bit (wall times aside).

    Experiments (NAMES; several may be given, none means all but the two calibrations):

    EXPERIMENTS (each experiment's line, from `experiments.paper.registry`)

    Run times: docs/performance.md (from the manifest of the run behind the docs)
    """
    from experiments.exec import make_executor
    from experiments.paper.reproduce import run_experiments
    from experiments.render.progress import Progress

    chosen = [n.value for n in names or []]
    with Progress() as progress, make_executor(workers, dask) as executor:
        written = run_experiments(
            chosen, out, quick=quick, seed=seed, progress=progress, executor=executor
        )
    typer.echo(f"{len(written)} files in {out}/ (see {out}/manifest.json)")


reproduce.__doc__ = reproduce.__doc__.replace(
    "    EXPERIMENTS (each experiment's line, from `experiments.paper.registry`)",
    textwrap.indent(help_lines(), "    "),
)


@app.command()
@handle_errors
def sweep(
    config: Annotated[
        Path | None,
        typer.Argument(help="sweep file (TOML), e.g. datasets/sweeps/sweep_slam_noise.toml"),
    ] = None,
    out: Annotated[Path, typer.Option(help="output folder")] = Path("sweep_out"),
    workers: Annotated[
        int | None,
        typer.Option(
            min=1,
            max=MAX_WORKERS,
            help="local worker processes (1: this process; at most 4096) [default: the file's "
            "[executor], else every core]",
        ),
    ] = None,
    dask: Annotated[
        str | None,
        typer.Option(
            envvar="TRUNKSLAM_DASK",
            callback=dask_address,
            help="run the trials on this Dask scheduler (tcp://host:8786) [default: "
            "$TRUNKSLAM_DASK, else the file's [executor]]",
        ),
    ] = None,
    fields: Annotated[
        Study | None,
        typer.Option(
            "--fields", help="print a study's fields and their defaults, and exit [default: no]"
        ),
    ] = None,
) -> None:
    """Run a study over a grid (or list) of configuration values: sweep.csv (tidy: point,
    swept values, method, metric, mean, std, n), a plot per swept field, sweep.json."""
    if fields is not None:
        from experiments.paper.sweep import fields_toml

        typer.echo(fields_toml(fields.value), nl=False)
        return
    if config is None:
        raise typer.BadParameter("a sweep file is needed", param_hint="CONFIG")
    from experiments.paper.sweep import run_sweep_file
    from experiments.render.progress import Progress

    with Progress() as progress:
        written = run_sweep_file(config, out, workers, dask, progress)
    typer.echo(f"{len(written)} files in {out}/ (see {out}/sweep.csv)")


@app.command()
@handle_errors
def report(
    results: Annotated[
        list[Path],
        typer.Argument(
            help="`trunkslam reproduce` folders (the first one's manifest.json is the "
            "snapshot's) and folders of benchmark tables (`make bench`'s bench_results)"
        ),
    ],
    docs: Annotated[
        Path,
        typer.Option(help="the snapshot folder the documentation reads (made by report, or new)"),
    ] = Path("docs/results"),
    readme: Annotated[
        str,
        typer.Option(
            metavar="PATH", help="README whose results-at-a-glance block is rewritten ('' for none)"
        ),
    ] = "README.md",
    pages: Annotated[
        str,
        typer.Option(
            metavar="PATH",
            help="the documentation pages whose macros must still resolve ('' to check none)",
        ),
    ] = "docs",
) -> None:
    """Refresh the documentation's results snapshot (docs/results/) and the README's
    results-at-a-glance table from result folders.

    The files the folders hold replace the snapshot's; its other files (the calibrations, the
    benchmarks, experiments these folders did not run) are kept. Nothing is changed when a
    folder is not a results folder, a table is corrupt, --docs holds a file report did not
    write, or a page's macro would no longer resolve."""
    from experiments.io.outputs import check_outputs, lock_folder
    from experiments.render.refresh import refresh_snapshot

    readme_path = Path(readme) if readme else None  # ('' is none: Path("") would be ".")
    pages_path = Path(pages) if pages else None
    check_outputs("report", inputs=results, files={"--readme": readme_path}, into={"--docs": docs})
    with lock_folder(docs, "--docs"):
        done = refresh_snapshot(results, docs, pages=pages_path, readme=readme_path)
    for line in _refresh_lines(done, docs, readme_path):
        typer.echo(line)


def _refresh_lines(done, docs: Path, readme: Path | None) -> list[str]:
    """What `report` did, in lines: replaced, added, kept (by origin), not refreshed."""
    lines = [
        f"{docs}/: {len(done.replaced)} replaced, {len(done.added)} added, "
        f"{sum(map(len, done.kept.values()))} kept (files)"
    ]
    for origin, names in done.kept.items():
        shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
        lines.append(f"  kept from {origin}: {shown}")
    if done.stale:
        lines.append(
            f"  not refreshed (their experiments ran again and did not write them): "
            f"{', '.join(done.stale)}"
        )
    if done.skipped:
        lines.append(f"  skipped (links or not regular files): {', '.join(done.skipped)}")
    if readme is not None:
        lines.append(f"{readme}: results at a glance {done.readme}")
    return lines

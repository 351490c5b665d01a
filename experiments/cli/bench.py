"""`trunkslam bench ...`: benchmarks that print measured figures."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from experiments.cli.base import MAX_WORKERS, bench_app, dask_address, handle_errors, numbers
from experiments.cli.choices import Association, ExperimentName

MAX_BENCH_TREES = 5000  # bench slam --trees: the filter's covariance, (3 + 2 n)^2 floats
MAX_CHUNK = 100_000  # bench smoother --chunks: poses per iSAM2 update (Victoria Park: 7,249)


def _bench_out(value: Path | None) -> Path | None:
    """`--out` of a benchmark, checked before the benchmark runs."""
    if value is not None:
        from experiments.errors import DataError
        from experiments.io.outputs import check_outputs

        try:
            check_outputs("bench", files={"--out": value})
        except DataError as exc:
            raise typer.BadParameter(str(exc)) from None
    return value


BenchOut = Annotated[
    Path | None,
    typer.Option(
        "--out",
        callback=_bench_out,
        help="also write the table to this Markdown file (the docs' performance page) "
        "[default: none]",
    ),
]


def emit(text: str, out: Path | None) -> None:
    """Print a benchmark's table, and write it to `out` when given (atomically)."""
    typer.echo(text)
    if out is not None:
        from experiments.io.writers import write_atomic

        write_atomic(out, text if text.endswith("\n") else text + "\n")


@bench_app.command("extract")
@handle_errors
def bench_extract(
    repeats: Annotated[
        int, typer.Option(min=1, max=100, help="passes over the 2000 scans (at most 100)")
    ] = 3,
    data: Annotated[
        Path | None,
        typer.Option(help="victoria_park folder [default: $TRUNKSLAM_DATA/victoria_park]"),
    ] = None,
    out: BenchOut = None,
) -> None:
    """Scans per second of each extractor on the 2000 real Victoria Park scans."""
    from experiments.bench.extract import bench_extract as bench
    from experiments.bench.extract import format_extract
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(repeats=repeats, root=data, progress=progress)
    emit(format_extract(rows), out)


@bench_app.command("association")
@handle_errors
def bench_association(
    repeats: Annotated[
        int, typer.Option(min=1, max=100_000, help="scans timed per method (at most 100,000)")
    ] = 200,
    seed: Annotated[int, typer.Option(min=0, help="random seed")] = 0,
    out: BenchOut = None,
) -> None:
    """Median time per scan of each association method at Victoria Park scale."""
    from experiments.bench.association import bench, format_table
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(repeats=repeats, seed=seed, progress=progress)
    emit(format_table(rows), out)


@bench_app.command("slam")
@handle_errors
def bench_slam(
    trees: Annotated[
        int,
        typer.Option(
            min=1,
            max=MAX_BENCH_TREES,
            help="trees along the avenue (the final map size; at most 5,000: the filter's "
            "covariance is then 0.8 GB)",
        ),
    ] = 800,
    association: Annotated[Association, typer.Option(help="data association")] = Association.ihgr,
    seed: Annotated[int, typer.Option(min=0, help="random seed")] = 0,
    out: BenchOut = None,
) -> None:
    """EKF-SLAM time per scan against the size of the map: an avenue of trees, and the full
    Victoria Park run when its data is there."""
    from experiments.bench.slam import bench, bench_victoria_park, format_table
    from experiments.errors import MissingDataError
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(n_trees=trees, association=association.value, seed=seed, progress=progress)
        try:
            rows += bench_victoria_park(association.value, progress=progress)
        except MissingDataError as exc:
            typer.echo(f"Victoria Park rows skipped: {exc}", err=True)
    emit(format_table(rows), out)


@bench_app.command("smoother")
@handle_errors
def bench_smoother(
    chunks: Annotated[
        str, typer.Option(help="comma-separated poses per iSAM2 update on GTSAM's graph")
    ] = "25",
    per_pose: Annotated[
        bool, typer.Option(help="also iSAM2 one pose at a time on GTSAM's graph (about 30 s)")
    ] = True,
    data: Annotated[
        Path | None,
        typer.Option(help="victoria_park folder [default: $TRUNKSLAM_DATA/victoria_park]"),
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="random seed of the tree-park run")] = 0,
    out: BenchOut = None,
) -> None:
    """Seconds of the GTSAM smoother (batch, iSAM2, iSAM2 + polish) on a tree-park run, the
    full Victoria Park run and GTSAM's own Victoria Park graph."""
    from experiments.bench.smoother import bench_smoother as bench
    from experiments.bench.smoother import format_table

    sizes = numbers("--chunks", chunks, len(chunks.split(",")))
    if any(v != int(v) or not 1 <= v <= MAX_CHUNK for v in sizes):
        raise typer.BadParameter(
            f"poses per update must be whole numbers in 1..{MAX_CHUNK}, got {chunks!r}",
            param_hint="--chunks",
        )
    sizes = [int(v) for v in sizes]
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(data, tuple(sizes), per_pose, seed, progress=progress)
    emit(format_table(rows), out)


@bench_app.command("cold")
@handle_errors
def bench_cold(
    commands: Annotated[
        str, typer.Option(help="comma-separated: check (make check), test (make test), quick")
    ] = "check,test,quick",
    repo: Annotated[
        Path | None,
        typer.Option(help="the git checkout to clone [default: the one holding trunkslam]"),
    ] = None,
    out: BenchOut = None,
) -> None:
    """A fresh clone's `make check`, `make test` and `reproduce --quick`, cold (numba's and
    pytest's caches removed) and warm (run again at once): wall and CPU seconds. The clone of
    the committed HEAD is installed in a temporary folder first (about a minute); the whole
    benchmark takes about half an hour on two cores."""
    from experiments.bench.cold import bench_cold as bench
    from experiments.bench.cold import format_cold
    from experiments.render.progress import Progress

    names = [n.strip() for n in commands.split(",") if n.strip()]
    with Progress() as progress:
        rows = bench(names, repo, progress=progress)
    emit(format_cold(rows), out)


@bench_app.command("reproduce")
@handle_errors
def bench_reproduce(
    names: Annotated[
        list[ExperimentName] | None,
        typer.Argument(help="experiments to run (default: those of `trunkslam reproduce`)"),
    ] = None,
    quick: Annotated[bool, typer.Option(help="the small-sample version")] = False,
    workers: Annotated[
        int | None,
        typer.Option(
            min=2,
            max=MAX_WORKERS,
            help="the parallel run's worker processes (at most 4096) [default: every core]",
        ),
    ] = None,
    dask: Annotated[
        str | None,
        typer.Option(
            callback=dask_address,
            help="also run on this Dask scheduler (tcp://host:8786) [default: no]",
        ),
    ] = None,
    out: BenchOut = None,
) -> None:
    """Wall time of `trunkslam reproduce` with 1 worker and with every core (and on a Dask
    scheduler), and whether the tables are the same."""
    from experiments.bench.reproduce import bench_reproduce as bench
    from experiments.bench.reproduce import format_table
    from experiments.render.progress import Progress

    chosen = [n.value for n in names or []]
    with Progress() as progress:
        rows = bench(chosen, quick, (1, workers), dask, progress)
    what = " ".join(chosen) or "(default experiments)"
    emit(format_table(rows, what + (" --quick" if quick else "")), out)


@bench_app.command("raycast")
@handle_errors
def bench_raycast(
    repeats: Annotated[
        int, typer.Option(min=1, max=100_000, help="calls timed per pass (at most 100,000)")
    ] = 300,
    seed: Annotated[int, typer.Option(min=0, help="random seed")] = 0,
    out: BenchOut = None,
) -> None:
    """Microseconds per 720-beam simulated scan on the bundled scenes and a random one."""
    from experiments.bench.raycast import bench_raycast as bench
    from experiments.bench.raycast import format_table
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(repeats=repeats, seed=seed, progress=progress)
    emit(format_table(rows), out)


@bench_app.command("startup")
@handle_errors
def bench_startup(
    repeats: Annotated[
        int, typer.Option(min=1, max=1000, help="timed runs of each command (at most 1000)")
    ] = 5,
    out: BenchOut = None,
) -> None:
    """Seconds until `trunkslam presets`, `trunkslam slam --help` and `trunkslam slam
    missing.npz` answer, each in fresh processes (median; target under 0.5 s)."""
    from experiments.bench.startup import bench_startup as bench
    from experiments.bench.startup import format_table
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(repeats=repeats, progress=progress)
    emit(format_table(rows), out)

"""`trunkslam bench ...`: benchmarks that print measured figures, one command per row of
`BENCHES`.

Every benchmark does the same around its own measurement: check its options, run with a
progress display, print its Markdown table and write it to `--out` when given. A row says what
differs: the command's name and help, its options (typer annotations, with `--out` added to
each) and `measure(progress, **options) -> table`, which imports the benchmark's module when
it runs (so `--help` stays light). A new benchmark is a new row.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass
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


def _load(target: str) -> Callable:
    """The function "module:name" names (imported now)."""
    module, name = target.split(":")
    return getattr(importlib.import_module(module), name)


def _simple(run: str, table: str, **arguments: str) -> Callable[..., str]:
    """A measure that calls `run(**options, progress=...)` (an option named in `arguments` is
    passed as the argument it names) and formats its rows with `table`."""

    def measure(progress, **options) -> str:
        kwargs = {arguments.get(k, k): v for k, v in options.items()}
        return _load(table)(_load(run)(**kwargs, progress=progress))

    return measure


def _measure_slam(progress, *, trees, association, seed) -> str:
    from experiments.bench.slam import bench, bench_victoria_park, format_table
    from experiments.errors import MissingDataError

    rows = bench(n_trees=trees, association=association.value, seed=seed, progress=progress)
    try:
        rows += bench_victoria_park(association.value, progress=progress)
    except MissingDataError as exc:
        typer.echo(f"Victoria Park rows skipped: {exc}", err=True)
    return format_table(rows)


def _chunk_sizes(options: dict) -> dict:
    """--chunks as whole numbers of poses per update, or a usage error naming it."""
    chunks = options["chunks"]
    sizes = numbers("--chunks", chunks, len(chunks.split(",")))
    if any(v != int(v) or not 1 <= v <= MAX_CHUNK for v in sizes):
        raise typer.BadParameter(
            f"poses per update must be whole numbers in 1..{MAX_CHUNK}, got {chunks!r}",
            param_hint="--chunks",
        )
    return {**options, "chunks": tuple(int(v) for v in sizes)}


def _measure_smoother(progress, *, chunks, per_pose, data, seed) -> str:
    from experiments.bench.smoother import bench_smoother as bench
    from experiments.bench.smoother import format_table

    return format_table(bench(data, chunks, per_pose, seed, progress=progress))


def _kept_table(options: dict) -> dict:
    """--keep read into the rows it keeps, or a usage error naming the file."""
    keep = options["keep"]
    if keep is None:
        return {**options, "keep": []}
    from experiments.bench.cold import read_cold, table_machine
    from experiments.errors import DataError
    from experiments.io.paths import check_input_file, read_text_file
    from experiments.io.provenance import machine

    try:  # a regular file, read up to 1 MiB (a FIFO or /dev/zero is refused)
        text = read_text_file(check_input_file(keep, "--keep table"), "bench table")
        rows = read_cold(text)
    except DataError as exc:
        raise typer.BadParameter(str(exc), param_hint="--keep") from None
    if not rows:
        raise typer.BadParameter(
            f"{keep}: no row of a `trunkslam bench cold` table in it", param_hint="--keep"
        )
    try:  # the table names one machine (processor and cores): rows of another cannot join it
        measured_on = table_machine(text)
    except DataError as exc:
        raise typer.BadParameter(f"{keep}: {exc}", param_hint="--keep") from None
    if measured_on.split(", ")[:2] != machine().split(", ")[:2]:
        raise typer.BadParameter(
            f"{keep}: measured on {measured_on}, not on this machine ({machine()})",
            param_hint="--keep",
        )
    return {**options, "keep": rows}


def _measure_cold(progress, *, commands, repo, keep) -> str:
    from experiments.bench.cold import bench_cold as bench
    from experiments.bench.cold import format_cold, keep_rows

    names = [n.strip() for n in commands.split(",") if n.strip()]
    return format_cold(keep_rows(bench(names, repo, progress=progress), keep))


def _measure_reproduce(progress, *, names, quick, workers, dask) -> str:
    from experiments.bench.reproduce import bench_reproduce as bench
    from experiments.bench.reproduce import format_table

    chosen = [n.value for n in names or []]
    rows = bench(chosen, quick, (1, workers), dask, progress)
    what = " ".join(chosen) or "(default experiments)"
    return format_table(rows, what + (" --quick" if quick else ""))


Data = Annotated[
    Path | None, typer.Option(help="victoria_park folder [default: $TRUNKSLAM_DATA/victoria_park]")
]
Seed = Annotated[int, typer.Option(min=0, help="random seed")]


@dataclass(frozen=True)
class Bench:
    """One `trunkslam bench NAME` command.

    name: the command's name; about: its help (the docstring a typer command would have).
    options: (parameter, typer annotation, default) of each option or argument, in order;
        `--out` follows them.
    measure: (progress, **options) -> the Markdown table; imports the benchmark when called.
    check: options -> options, checked and converted before the progress display starts
        (a usage error raises typer.BadParameter) [default: as given].
    """

    name: str
    about: str
    options: tuple[tuple[str, object, object], ...]
    measure: Callable[..., str]
    check: Callable[[dict], dict] = dict


BENCHES = (
    Bench(
        "extract",
        "Scans per second of each extractor on the 2000 real Victoria Park scans.",
        (
            (
                "repeats",
                Annotated[
                    int,
                    typer.Option(min=1, max=100, help="passes over the 2000 scans (at most 100)"),
                ],
                3,
            ),
            ("data", Data, None),
        ),
        _simple(
            "experiments.bench.extract:bench_extract",
            "experiments.bench.extract:format_extract",
            data="root",
        ),
    ),
    Bench(
        "association",
        "Median time per scan of each association method at Victoria Park scale.",
        (
            (
                "repeats",
                Annotated[
                    int,
                    typer.Option(
                        min=1, max=100_000, help="scans timed per method (at most 100,000)"
                    ),
                ],
                200,
            ),
            ("seed", Seed, 0),
        ),
        _simple(
            "experiments.bench.association:bench", "experiments.bench.association:format_table"
        ),
    ),
    Bench(
        "slam",
        """EKF-SLAM time per scan against the size of the map: an avenue of trees, and the full
    Victoria Park run when its data is there.""",
        (
            (
                "trees",
                Annotated[
                    int,
                    typer.Option(
                        min=1,
                        max=MAX_BENCH_TREES,
                        help="trees along the avenue (the final map size; at most 5,000: the "
                        "filter's covariance is then 0.8 GB)",
                    ),
                ],
                800,
            ),
            (
                "association",
                Annotated[Association, typer.Option(help="data association")],
                Association.ihgr,
            ),
            ("seed", Seed, 0),
        ),
        _measure_slam,
    ),
    Bench(
        "smoother",
        """Seconds of the GTSAM smoother (batch, iSAM2, iSAM2 + polish) on a tree-park run, the
    full Victoria Park run and GTSAM's own Victoria Park graph.""",
        (
            (
                "chunks",
                Annotated[
                    str,
                    typer.Option(help="comma-separated poses per iSAM2 update on GTSAM's graph"),
                ],
                "25",
            ),
            (
                "per_pose",
                Annotated[
                    bool,
                    typer.Option(
                        help="also iSAM2 one pose at a time on GTSAM's graph (about 30 s)"
                    ),
                ],
                True,
            ),
            ("data", Data, None),
            (
                "seed",
                Annotated[int, typer.Option(min=0, help="random seed of the tree-park run")],
                0,
            ),
        ),
        _measure_smoother,
        check=_chunk_sizes,
    ),
    Bench(
        "cold",
        """A fresh clone's `make check`, `make test` and `reproduce --quick`, cold (numba's and
    pytest's caches removed) and warm (run again at once): wall and CPU seconds. The clone of
    the committed HEAD is installed in a temporary folder first (about a minute); the whole
    benchmark takes about half an hour on two cores.""",
        (
            (
                "commands",
                Annotated[
                    str,
                    typer.Option(
                        help="comma-separated: check (make check), test (make test), quick"
                    ),
                ],
                "check,test,quick",
            ),
            (
                "repo",
                Annotated[
                    Path | None,
                    typer.Option(
                        help="the git checkout to clone [default: the one holding trunkslam]"
                    ),
                ],
                None,
            ),
            (
                "keep",
                Annotated[
                    Path | None,
                    typer.Option(
                        help="a table this benchmark wrote before (e.g. the --out file): its "
                        "rows of the commands not run now are kept, each naming the commit it "
                        "measured [default: none]"
                    ),
                ],
                None,
            ),
        ),
        _measure_cold,
        check=_kept_table,
    ),
    Bench(
        "reproduce",
        """Wall time of `trunkslam reproduce` with 1 worker and with every core (and on a Dask
    scheduler), and whether the tables are the same.""",
        (
            (
                "names",
                Annotated[
                    list[ExperimentName] | None,
                    typer.Argument(
                        help="experiments to run (default: those of `trunkslam reproduce`)"
                    ),
                ],
                None,
            ),
            ("quick", Annotated[bool, typer.Option(help="the small-sample version")], False),
            (
                "workers",
                Annotated[
                    int | None,
                    typer.Option(
                        min=2,
                        max=MAX_WORKERS,
                        help="the parallel run's worker processes (at most 4096) [default: "
                        "every core]",
                    ),
                ],
                None,
            ),
            (
                "dask",
                Annotated[
                    str | None,
                    typer.Option(
                        callback=dask_address,
                        help="also run on this Dask scheduler (tcp://host:8786) [default: no]",
                    ),
                ],
                None,
            ),
        ),
        _measure_reproduce,
    ),
    Bench(
        "raycast",
        "Microseconds per 720-beam simulated scan on the bundled scenes and a random one.",
        (
            (
                "repeats",
                Annotated[
                    int,
                    typer.Option(min=1, max=100_000, help="calls timed per pass (at most 100,000)"),
                ],
                300,
            ),
            ("seed", Seed, 0),
        ),
        _simple(
            "experiments.bench.raycast:bench_raycast", "experiments.bench.raycast:format_table"
        ),
    ),
    Bench(
        "startup",
        """Seconds until `trunkslam presets`, `trunkslam slam --help` and `trunkslam slam
    missing.npz` answer, each in fresh processes (median; target under 0.5 s), and until a
    first `trunkslam slam` (empty numba cache) says its first line (target under 2 s).""",
        (
            (
                "repeats",
                Annotated[
                    int,
                    typer.Option(min=1, max=1000, help="timed runs of each command (at most 1000)"),
                ],
                5,
            ),
        ),
        _simple(
            "experiments.bench.startup:bench_startup", "experiments.bench.startup:format_table"
        ),
    ),
)


def add_command(bench: Bench) -> None:
    """`trunkslam bench NAME` from its row: options checked, measured with progress, printed
    and written to --out."""

    def command(**options) -> None:
        out = options.pop("out")
        options = bench.check(options)
        from experiments.render.progress import Progress

        with Progress() as progress:
            text = bench.measure(progress, **options)
        emit(text, out)

    params = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=hint)
        for name, hint, default in (*bench.options, ("out", BenchOut, None))
    ]
    command.__signature__ = inspect.Signature(params, return_annotation=None)
    command.__annotations__ = {p.name: p.annotation for p in params} | {"return": None}
    command.__doc__ = bench.about
    command.__name__ = command.__qualname__ = f"bench_{bench.name}"
    bench_app.command(bench.name)(handle_errors(command))


for _bench in BENCHES:
    add_command(_bench)

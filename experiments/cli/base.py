"""The app, its groups and what every command shares: the app's own options (`-v`,
`--threads`, `--version`), the one place the project's errors become `error: ...` and exit code 1
(`handle_errors`), and the small parsers and checks of option values.

Heavy imports happen inside the commands so `--help` is instant.
"""

from __future__ import annotations

import functools
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Annotated

import typer

from experiments.render.cli_style import TrunkslamGroup  # light: metavars, -v anywhere

__all__ = [
    "MAX_WORKERS",
    "app",
    "bench_app",
    "check_input",
    "convert_app",
    "dask_address",
    "handle_errors",
    "numbers",
]

app = typer.Typer(
    cls=TrunkslamGroup,
    name="trunkslam",
    help="Tree-trunk features from 2D laser scans, data association and EKF-SLAM.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # help texts are Markdown: "[default: ...]" and "[features]" are shown, not read as rich tags
    rich_markup_mode="markdown",
)
convert_app = typer.Typer(
    help="Convert a dataset into a trunkslam sequence file (.npz).", rich_markup_mode="markdown"
)
bench_app = typer.Typer(help="Benchmarks that print measured figures.", rich_markup_mode="markdown")
app.add_typer(convert_app, name="convert")
app.add_typer(bench_app, name="bench")

log = logging.getLogger("trunkslam")


def project_errors() -> tuple[type[BaseException], ...]:
    """The exception types that mean bad input, not a bug: shown as one line, exit code 1."""
    from experiments.errors import input_errors

    return input_errors()


def handle_errors(fn):
    """Map the project's errors to `error: <message>` and exit code 1."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except project_errors() as exc:
            typer.echo(f"error: {exc}", err=True)
            _exit_if_stuck(1)
            raise typer.Exit(1) from None
        except KeyboardInterrupt as exc:  # Ctrl-C, or a stop signal (experiments.exec.signals)
            signum = getattr(exc, "signum", None)
            if signum is None:
                raise  # Ctrl-C: typer's exit code 130
            name = signal.Signals(signum).name
            typer.echo(f"error: stopped by {name}; earlier outputs left as they were", err=True)
            raise typer.Exit(128 + signum) from None

    return wrapper


def _exit_if_stuck(code: int) -> None:
    """End the process now when a recording's writer was stopped by a write error: rerun
    would wait for it forever at exit (`experiments.render.viz.writer_stopped`). Every file
    has been cleaned up by then (the `with` blocks have exited)."""
    viz = sys.modules.get("experiments.render.viz")
    if viz is not None and viz.writer_stopped():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def numbers(option: str, text: str, n: int) -> list[float]:
    """`text` as n comma-separated finite numbers, or a usage error naming the option."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(abs(v) < float("inf") for v in values):
        raise typer.BadParameter(
            f"expected {n} comma-separated numbers, got {text!r}", param_hint=option
        )
    return values


MAX_WORKERS = 4096  # --workers, --threads: processes or threads of one machine


def dask_address(value: str | None) -> str | None:
    """--dask checked before any work: a scheduler address of a scheme dask knows."""
    if value is not None:
        from experiments.errors import ConfigError
        from experiments.exec.cluster import check_address

        try:
            check_address(value)
        except ConfigError as exc:
            raise typer.BadParameter(str(exc)) from None
    return value


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever sys.stderr is when a record comes (not the one at set-up)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import version

        typer.echo(f"trunkslam {version('trunkslam')}")
        raise typer.Exit()


@app.callback()
def main(
    ctx: typer.Context,
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose",
            "-v",
            help="log what the commands do, progress detail included (before or after the "
            "command: trunkslam -v slam ..., trunkslam slam ... -v)",
        ),
    ] = False,
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="print the version and exit"
        ),
    ] = False,
    threads: Annotated[
        int | None,
        typer.Option(
            "--threads",
            min=1,
            max=MAX_WORKERS,
            help="BLAS/OpenMP threads of this process (the filter is fastest with one; "
            "reproduce and sweep use one per worker) [default: $OMP_NUM_THREADS, else 1]",
        ),
    ] = None,
) -> None:
    from experiments.exec.once import OnceFilter
    from experiments.exec.signals import interrupt_on_stop_signals
    from experiments.exec.threads import set_threads

    set_threads(threads)  # first: before numpy, whose BLAS reads it when it starts
    # SIGTERM and SIGHUP clean up as Ctrl-C does; the handlers go when the command ends
    ctx.call_on_close(interrupt_on_stop_signals())
    level = logging.INFO if verbose else logging.WARNING
    if _terminal():  # log lines print above the progress bars
        from rich.logging import RichHandler

        from experiments.render.progress import CONSOLE

        handler = RichHandler(console=CONSOLE, show_path=False, show_time=False)
        handler.addFilter(OnceFilter())  # each warning once per command
        logging.basicConfig(level=level, format="%(message)s", handlers=[handler], force=True)
    else:
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(levelname)s %(message)s"))
        handler.addFilter(OnceFilter())
        logging.basicConfig(level=level, handlers=[handler], force=True)


def _terminal() -> bool:
    """Whether stderr is rich's terminal; rich (0.1 s to import) only loads when it may be."""
    env = os.environ
    if not (sys.stderr.isatty() or env.get("TTY_COMPATIBLE") == "1" or env.get("FORCE_COLOR")):
        return False  # rich would say no too (rich.console.Console.is_terminal)
    from experiments.render.progress import CONSOLE

    return CONSOLE.is_terminal


def check_input(path: Path | None, what: str) -> None:
    """A missing or unreadable input refused before the command's heavy imports load."""
    if path is not None:
        from experiments.io.paths import check_input_file  # light: no numpy

        check_input_file(path, what)

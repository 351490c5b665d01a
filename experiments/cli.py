"""The `trunkslam` command line: typer only. Each command parses, calls one function, prints.

Heavy imports happen inside the commands so `--help` is instant. `handle_errors` is the one
place that turns the project's own errors (and OSError from files) into `error: ...` and exit
code 1; anything else is a bug and shows its traceback.
"""

from __future__ import annotations

import functools
import logging
import os
import signal
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from experiments.bundled import scene_names  # light: lists the package's scenes for the help
from experiments.render.cli_style import TrunkslamGroup, counted  # light: metavars, -v anywhere

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


# Option choices. The values are written out here (importing the packages would make --help
# slow); tests/experiments/test_cli.py checks them against features.METHODS and the rest.
class ExtractMethod(StrEnum):
    paper = "paper"
    geometric = "geometric"
    kasa = "kasa"
    taubin = "taubin"
    bailey = "bailey"


class SlamFeatures(StrEnum):
    paper = "paper"
    geometric = "geometric"
    bailey = "bailey"
    detections = "detections"


class Association(StrEnum):
    ihgr = "ihgr"
    ihgr_window = "ihgr-window"
    jcbb = "jcbb"
    nn = "nn"


class SmootherSolver(StrEnum):
    batch = "batch"
    isam2 = "isam2"


class Robust(StrEnum):
    none = "none"
    huber = "huber"
    cauchy = "cauchy"


class SmootherMeasurements(StrEnum):
    ekf = "ekf"
    all = "all"


class EdgeNoise(StrEnum):  # experiments.io.g2o.EDGE_NOISE
    information = "information"
    covariance = "covariance"


class LineTest(StrEnum):
    lrt = "lrt"
    paper = "paper"


class Sensor(StrEnum):
    pls200 = "pls200"
    lms200 = "lms200"


class RosOdometry(StrEnum):  # experiments.io.rosbag.ODOMETRY_SOURCES
    twist = "twist"
    pose = "pose"


class ExperimentName(StrEnum):
    features = "features"
    table1 = "table1"
    table2 = "table2"
    circle_sweep = "circle-sweep"
    table3 = "table3"
    table4 = "table4"
    association = "association"
    victoria_park = "victoria-park"
    victoria_park_rfs = "victoria-park-rfs"
    smoother = "smoother"
    noise_calibration = "noise-calibration"
    victoria_park_calibration = "victoria-park-calibration"
    victoria_park_map_policy = "victoria-park-map-policy"
    loop_closure = "loop-closure"
    sim_clutter = "sim-clutter"
    victoria_park_split_half = "victoria-park-split-half"


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


def _numbers(option: str, text: str, n: int) -> list[float]:
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
MAX_BENCH_TREES = 5000  # bench slam --trees: the filter's covariance, (3 + 2 n)^2 floats
MAX_CHUNK = 100_000  # bench smoother --chunks: poses per iSAM2 update (Victoria Park: 7,249)


def _dask_address(value: str | None) -> str | None:
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


def _emit(text: str, out: Path | None) -> None:
    """Print a benchmark's table, and write it to `out` when given (atomically)."""
    typer.echo(text)
    if out is not None:
        from experiments.io.writers import write_atomic

        write_atomic(out, text if text.endswith("\n") else text + "\n")


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


@app.command()
@handle_errors
def extract(
    input: Annotated[Path, typer.Argument(help="sequence file (.npz), see datasets/FORMAT.md")],
    out: Annotated[Path, typer.Option(help="features JSON to write")] = Path("features.json"),
    method: Annotated[ExtractMethod, typer.Option(help="circle extractor")] = ExtractMethod.paper,
    sigma_r: Annotated[
        float | None,
        typer.Option(
            help="range noise sigma the extractor assumes, m (paper/geometric only) [default: 0.02]"
        ),
    ] = None,
    line_test: Annotated[
        LineTest | None,
        typer.Option(help="line test: lrt or paper (eq. 5); paper/geometric only [default: lrt]"),
    ] = None,
    rerun: Annotated[
        Path | None, typer.Option(help="also write a rerun recording (.rrd) [default: none]")
    ] = None,
    config: Annotated[
        str | None,
        typer.Option(
            "--config",
            help="the extractor's parameters from a configuration's [features] section: a "
            "TOML file or a preset of `trunkslam presets` (--method still chooses the "
            "extractor) [default: the extractor's defaults]",
        ),
    ] = None,
) -> None:
    """Extract circles, lines, edges and clutter from every scan of a sequence file."""
    _check_input(input, "sequence file")
    from experiments.pipeline.extract import run_extract
    from experiments.render.progress import Progress

    features = None
    if config is not None:
        from experiments.io.config_file import load_slam_config

        features = load_slam_config(config).features
    with Progress() as progress:
        s = run_extract(
            input,
            out,
            method.value,
            sigma_r_m=sigma_r,
            line_test=None if line_test is None else line_test.value,
            rerun_path=rerun,
            progress=progress,
            features=features,
            config_file=None if config is None else Path(config),
        )
    typer.echo(f"{counted(s['scans'], 'scan')} -> {out} ({counted(s['circles'], 'circle')})")


@convert_app.command("victoria-park")
@handle_errors
def convert_victoria_park(
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("vp.npz"),
    full: Annotated[
        bool,
        typer.Option(
            help="all 7249 scans with the published detections only (default: the 2000 scans "
            "with raw laser data, detections beside them)"
        ),
    ] = False,
    data: Annotated[
        Path | None,
        typer.Option(help="victoria_park folder [default: $TRUNKSLAM_DATA/victoria_park]"),
    ] = None,
) -> None:
    """Victoria Park (odometry, GPS, raw scans and/or published detections) as one sequence file."""
    from experiments.io.outputs import check_outputs
    from experiments.io.paths import victoria_park_dir
    from experiments.io.sequence_file import save_sequence
    from experiments.io.victoria_park import load_victoria_park
    from experiments.render.progress import Progress

    root = data if data is not None else victoria_park_dir()
    check_outputs("convert", inputs=[root], files={"--out": out})  # every file of the data
    with Progress() as progress:
        seq = load_victoria_park(root, full=full, progress=progress)
        progress(f"writing {out.name}", 0, 1)
        save_sequence(seq, out)
        progress(f"writing {out.name}", 1, 1)
    kind = "detections only" if full else "raw scans and detections"
    typer.echo(f"{seq.n_scans} scans ({kind}, {seq.det_scan.size} detections) -> {out}")


@convert_app.command("rosbag")
@handle_errors
def convert_rosbag(
    bag: Annotated[
        Path,
        typer.Argument(help="a ROS 1 .bag, a ROS 2 bag folder (sqlite3 or MCAP) or an .mcap file"),
    ],
    scan: Annotated[str, typer.Option(help="the sensor_msgs/LaserScan topic")],
    odom: Annotated[str, typer.Option(help="the nav_msgs/Odometry topic")],
    gps: Annotated[
        str | None, typer.Option(help="a sensor_msgs/NavSatFix topic [default: none, no GPS]")
    ] = None,
    laser_pose: Annotated[
        str | None,
        typer.Option(
            help="x,y,yaw of the laser in the robot's frame (m, m, rad) [default: from /tf_static]"
        ),
    ] = None,
    odometry: Annotated[
        RosOdometry,
        typer.Option(
            help="twist: a unicycle's speed and yaw rate; pose: increments of the odometry's poses"
        ),
    ] = RosOdometry.twist,
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("seq.npz"),
) -> None:
    """A robot's ROS bag (laser scans, wheel odometry, optional GPS) as one sequence file."""
    from experiments.io.outputs import check_outputs
    from experiments.io.rosbag import bag_inputs, read_rosbag
    from experiments.io.sequence_file import save_sequence
    from experiments.render.progress import Progress

    mount = None if laser_pose is None else _numbers("--laser-pose", laser_pose, 3)
    check_outputs("convert", inputs=bag_inputs(bag), files={"--out": out})
    with Progress() as progress:
        run = read_rosbag(
            bag,
            scan=scan,
            odom=odom,
            gps=gps,
            laser_pose=mount,
            odometry=odometry.value,
            progress=progress,
        )
        save_sequence(run.sequence, out)
    typer.echo(run.summary() + f" -> {out}")


@app.command()
@handle_errors
def simulate(
    scene: Annotated[
        str, typer.Argument(help=f"a bundled scene ({', '.join(scene_names())}) or a JSON path")
    ],
    pose: Annotated[str, typer.Option(help="x,y,theta of the sensor in the world (m, m, rad)")],
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("scan.npz"),
    sensor: Annotated[Sensor, typer.Option(help="sensor preset")] = Sensor.pls200,
    back_to_back: Annotated[bool, typer.Option(help="two sensors back to back (360 deg)")] = False,
    noise: Annotated[
        float | None,
        typer.Option(
            min=0.0, max=100.0, help="range noise sigma, m [default: 0.01 (the preset's)]"
        ),
    ] = None,
    seed: Annotated[int, typer.Option(min=0, help="random seed")] = 0,
) -> None:
    """Simulate one scan of a scene from a pose and write it as a sequence file."""
    from experiments.io.outputs import check_outputs
    from experiments.io.sequence_file import save_sequence
    from experiments.sim import simulate_to_sequence

    check_outputs("simulate", inputs=[Path(scene)], files={"--out": out})
    seq = simulate_to_sequence(
        scene,
        [_numbers("--pose", pose, 3)],
        sensor_name=sensor.value,
        back_to_back=back_to_back,
        noise_m=noise,
        seed=seed,
    )
    save_sequence(seq, out)
    typer.echo(f"1 scan of {scene} -> {out}")


@app.command("simulate-drive")
@handle_errors
def simulate_drive(
    scene: Annotated[str, typer.Argument(help="scene with a route (scan_positions)")] = "tree_park",
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("run.npz"),
    scans: Annotated[int, typer.Option(min=1, help="scans in the run (5 Hz: 0.2 s a scan)")] = 240,
    seed: Annotated[int, typer.Option(min=0, help="random seed")] = 0,
) -> None:
    """Simulate a Cycab drive around a scene's route (experiment 2's set-up): scans, odometry,
    DGPS and truth, as one sequence file."""
    import numpy as np

    from experiments.io.outputs import check_outputs
    from experiments.io.sequence_file import save_sequence
    from experiments.sim import CycabParams, simulate_cycab_run

    check_outputs("simulate-drive", inputs=[Path(scene)], files={"--out": out})
    seq = simulate_cycab_run(np.random.default_rng(seed), scene, CycabParams(n_scans=scans))
    save_sequence(seq, out)
    typer.echo(f"{counted(seq.n_scans, 'scan')} of {scene} ({seq.scan_t[-1]:.1f} s) -> {out}")


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
            callback=_dask_address,
            help="run the trials on this Dask scheduler (tcp://host:8786) instead of local "
            "processes; needs trunkslam[dask] [default: $TRUNKSLAM_DASK, else none]",
        ),
    ] = None,
) -> None:
    """Run the paper's experiments: tables (.md/.csv), figures (.png), recordings (.rrd).

    The trials run on every local core (--workers), or on a Dask cluster (--dask); the numbers
    are the same whichever, bit for bit (wall times aside).

    Experiments (NAMES; several may be given, none means all but the two calibrations):

    - features: classification of simulated trunks, the Victoria Park scan figure, features.rrd

    - table1, table2: circle-centre and radius accuracy on the pillar court (one run), circles.rrd

    - circle-sweep: CE and RE against range, radius and noise, with the Cramer-Rao bound

    - table3, table4: EKF-SLAM Monte Carlo on the simulated tree park (one run), with the GTSAM
    smoother's columns, slam.rrd

    - association: IHGR, JCBB and NN side by side

    - victoria-park: EKF-SLAM on the real run against GPS (needs the data), victoria_park.rrd

    - victoria-park-rfs: the full run under the published RFS protocol, exactly (100 clutter
    draws; only when named)

    - smoother: GTSAM's Victoria Park graph solved; the full run's EKF against its smoother

    - noise-calibration: measurement-noise model of each extractor

    - victoria-park-calibration: the ute's noise and laser yaw (only when named)

    - victoria-park-map-policy: the map policy's confirm_scans and pruning settings from scans
    1-2000 (only when named)

    - loop-closure: simulated loops in a park and an orchard, loop closure off and on
    (only when named)

    - sim-clutter: the map by object class in a simulated park with clutter (only when named)

    - victoria-park-split-half: map figures judged on a half no setting saw (only when named)

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


class Study(StrEnum):
    association = "association"
    slam = "slam"
    circles = "circles"


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
            callback=_dask_address,
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


@app.command()
@handle_errors
def presets() -> None:
    """The presets `--config NAME` takes (experiments/presets/NAME.toml, shipped in the
    package), one line each."""
    from experiments.io.config_file import presets as known

    for name, about in known().items():
        typer.echo(f"{name:20s} {about}")


# The options of `trunkslam slam` that replace one setting of the configuration each.
ConfigOption = Annotated[
    str | None,
    typer.Option(
        "--config",
        help="the run's settings: a TOML file (a run's config.toml reproduces it) or a "
        "preset of `trunkslam presets` [default: the built-in settings, SlamConfig()]",
    ),
]
FeaturesOption = Annotated[
    SlamFeatures | None,
    typer.Option(
        "--features",
        help="replaces the settings' [features] method: an extractor on the raw scans, or "
        "the sequence's detections [default: the settings', paper]",
    ),
]
FeaturesFileOption = Annotated[
    Path | None,
    typer.Option(
        "--features-file",
        help="features JSON from `trunkslam extract`, used instead of extracting "
        "([features] file) [default: none]",
    ),
]
AssociationOption = Annotated[
    Association | None,
    typer.Option(
        "--association",
        help="replaces the settings' [association] method: single-scan IHGR, the K-scan "
        "IHGR window (K: --window), JCBB or NN [default: the settings', ihgr]",
    ),
]
WindowOption = Annotated[
    int | None,
    typer.Option(
        "--window",
        min=1,
        max=8,
        help="K of the IHGR window (implies --association ihgr-window) "
        "[default: the settings' window_scans, 3]",
    ),
]
HeadingOption = Annotated[
    float | None,
    typer.Option(
        "--initial-heading",
        help="start heading, rad, when starting from GPS ([start] initial_heading_rad) "
        "[default: from the GPS fit]",
    ),
]
EllipseOption = Annotated[
    float,
    typer.Option(
        "--ellipse-scale",
        min=0.01,
        max=1e6,
        help="covariance ellipses in the recording are drawn this many times their 95% size "
        "(x1: true size)",
    ),
]


@app.command("slam")
@handle_errors
def slam_cmd(
    input: Annotated[
        Path | None, typer.Argument(help="sequence file (.npz), see datasets/FORMAT.md")
    ] = None,
    config: ConfigOption = None,
    features: FeaturesOption = None,
    features_file: FeaturesFileOption = None,
    association: AssociationOption = None,
    window: WindowOption = None,
    initial_heading: HeadingOption = None,
    dump_config: Annotated[
        bool, typer.Option(help="print the resolved settings as TOML and exit")
    ] = False,
    out: Annotated[Path, typer.Option(help="output folder")] = Path("slam_out"),
    rerun: Annotated[
        Path | None, typer.Option(help="also write a rerun recording (.rrd) [default: none]")
    ] = None,
    ellipse_scale: EllipseOption = 10.0,
    smooth: Annotated[
        bool, typer.Option(help="then re-solve the run with the GTSAM smoother (batch)")
    ] = False,
    reference_map: Annotated[
        Path | None,
        typer.Option(
            help="score the map against this one (CSV of x,y in metres, the run's frame): "
            "GOSPA and OSPA at c = 1 and 20 m in summary.json [default: none]"
        ),
    ] = None,
) -> None:
    """EKF-SLAM over a sequence as its settings say: trajectory (TUM and CSV with covariance),
    map, config.toml (the whole configuration: `--config` with it reproduces the run), summary,
    and the run log the smoother reads (`trunkslam smooth`)."""
    if config is None and not dump_config:  # a --config's errors are said first, as ever
        _check_input(input, "sequence file")
    from experiments.io.config_file import config_toml, load_slam_config
    from experiments.pipeline.slam import run_slam_file
    from experiments.render.progress import Progress
    from slam import SlamConfig

    cfg = load_slam_config(config) if config is not None else SlamConfig()
    cfg = _slam_overrides(
        cfg,
        features=features,
        features_file=features_file,
        association=association,
        window=window,
        initial_heading=initial_heading,
    )
    if dump_config:
        typer.echo(config_toml(cfg, f"trunkslam slam settings ({config or 'built-in'})"), nl=False)
        return
    if input is None:
        raise typer.BadParameter("a sequence file is needed", param_hint="INPUT")
    config_file = None if config is None else Path(config)  # an input (a preset's name: none)
    with _held(out, smooth):
        with Progress() as progress:
            s = run_slam_file(
                input,
                cfg,
                out,
                rerun_path=rerun,
                progress=lambda done, total: (
                    progress("slam", done, total) if done % 10 == 0 or done == total else None
                ),
                ellipse_scale=ellipse_scale,
                inputs=(config_file,),
                reference_map=reference_map,
            )
        typer.echo(f"{_slam_words(s)} -> {out}/")
        if smooth:
            from experiments.pipeline.smooth import smooth_run

            with Progress() as progress:
                summary = smooth_run(out, progress=_smoother_progress(progress))
            _echo_smoothed(summary)


def _slam_words(s: dict) -> str:
    """A slam run's summary in one line: scans, landmarks, GPS and truth errors, time, GOSPA."""
    err = _gps_words(s.get("gps")) + _truth_words(s.get("truth"))
    done = f"{counted(s['n_scans'], 'scan')}, {counted(s['landmarks'], 'landmark')}{err}"
    done += f", {s['seconds']:.1f} s" + _compiling_words(s.get("compile_s"))
    if "reference_map" in s:
        g = s["reference_map"]["gospa_20m"]
        done += f", GOSPA {g['distance']:.2f} m (c = 20 m) against the reference map"
    return done


def _check_input(path: Path | None, what: str) -> None:
    """A missing or unreadable input refused before the command's heavy imports load."""
    if path is not None:
        from experiments.io.paths import check_input_file  # light: no numpy

        check_input_file(path, what)


def _held(out: Path, smooth: bool):
    """slam --smooth: the --out folder held from the run to the end of its smoothing, so that
    no other command comes in between (`experiments.io.outputs.lock_folder`)."""
    import contextlib

    from experiments.io.outputs import lock_folder

    return lock_folder(out, "--out") if smooth else contextlib.nullcontext()


def _slam_overrides(cfg, *, features, features_file, association, window, initial_heading):
    """The one place the command line's options replace settings of the configuration."""
    changes = {}
    if features is not None:
        changes["features.method"] = features.value
    if features_file is not None:
        changes["features.file"] = str(features_file)
    if window is not None:
        if association not in (None, Association.ihgr, Association.ihgr_window):
            raise typer.BadParameter(
                f"--window is the IHGR window's K; not for --association {association.value}",
                param_hint="--window",
            )
        association = Association.ihgr_window
        changes["association.window_scans"] = window
    if association is not None:
        changes["association.method"] = association.value
    if initial_heading is not None:
        changes["start.initial_heading_rad"] = initial_heading
    return cfg.with_(**changes) if changes else cfg


def _gps_words(gps: dict | None) -> str:
    """ ", 0.03 m RMS from GPS", or what the summary says when it has no such figure."""
    if not gps:
        return ""
    if gps.get("all_rmse") is None:
        return ", not scored against GPS (no fix within the run; see not_computed in summary.json)"
    return f", {gps['all_rmse']:.2f} m RMS from GPS"


def _compiling_words(seconds: float | None) -> str:
    """ " (+ 75 s compiling kernels, first run only)" when the run compiled kernels."""
    if not seconds or seconds < 0.05:
        return ""
    return f" (+ {seconds:.0f} s compiling kernels, first run only)"


def _truth_words(truth: dict | None) -> str:
    """ ", 0.02 m RMS from truth" (evo_ape's figure against truth.tum), or nothing."""
    if not truth or truth.get("rmse_m") is None:
        return ""
    return f", {truth['rmse_m']:.3f} m RMS from truth"


def _echo_smoothed(s: dict) -> None:
    err = _gps_words(s.get("gps"))
    chi2 = "n/a" if s.get("chi2_per_dof") is None else f"{s['chi2_per_dof']:.3f}"
    typer.echo(
        f"smoothed ({s['solver']}): chi2/dof {chi2} after {s['iterations']} "
        f"iterations{err}, {s['seconds']:.1f} s + {s['seconds_marginals']:.1f} s covariances "
        f"-> {s['run_dir']}/"
    )


@app.command("smooth")
@handle_errors
def smooth_cmd(
    run_dir: Annotated[
        Path,
        typer.Argument(
            help="output folder of `trunkslam slam`, or a 2D graph file in GTSAM's g2o "
            "conventions (.g2o; see docs/graph-files.md)"
        ),
    ],
    solver: Annotated[
        SmootherSolver, typer.Option(help="batch Levenberg-Marquardt, or iSAM2 fed scan by scan")
    ] = SmootherSolver.batch,
    polish: Annotated[bool, typer.Option(help="batch Levenberg-Marquardt after iSAM2")] = False,
    robust: Annotated[
        Robust, typer.Option(help="robust kernel on the measurement factors")
    ] = Robust.none,
    measurements: Annotated[
        SmootherMeasurements,
        typer.Option(
            help="ekf: the measurements the filter used; all: also the tentative sightings of "
            "mapped landmarks"
        ),
    ] = SmootherMeasurements.ekf,
    isam2_every: Annotated[int, typer.Option(min=1, help="scans per iSAM2 update")] = 1,
    covariances: Annotated[
        bool, typer.Option(help="marginal covariances of every pose and landmark")
    ] = True,
    out: Annotated[
        Path | None,
        typer.Option(
            help="a graph file's solution (g2o) [default: GRAPH_smoothed.g2o beside it]; not "
            "for a run folder"
        ),
    ] = None,
    skip_tag: Annotated[
        list[str] | None,
        typer.Option(
            help="a graph file's lines of this tag are passed over (as GTSAM's readG2o passes "
            "over every tag it does not know; repeatable) [default: none, an unknown tag is an "
            "error]"
        ),
    ] = None,
    edge_noise: Annotated[
        EdgeNoise,
        typer.Option(help="what a graph file's six odometry noise numbers are (g2o: information)"),
    ] = EdgeNoise.information,
) -> None:
    """Re-solve a `trunkslam slam` run with the GTSAM smoother (same odometry, measurements and
    associations): trajectory_smoothed.tum/.csv, map_smoothed.csv, smoother.json. Or solve a
    graph file (`export-graph`'s, GTSAM's): its solution as a g2o file (--out)."""
    if run_dir.is_file():
        if measurements is not SmootherMeasurements.ekf:
            raise typer.BadParameter(
                "not for a graph file (its factors are given)", param_hint="--measurements"
            )
        opts = dict(polish=polish, robust=robust, every=isam2_every, skip=skip_tag)
        return _smooth_graph(run_dir, out, solver, edge_noise=edge_noise, **opts)
    if out is not None or skip_tag or edge_noise is not EdgeNoise.information:
        raise typer.BadParameter(
            "--out, --skip-tag and --edge-noise are for a graph file, not a run folder",
            param_hint="RUN_DIR",
        )
    from experiments.pipeline.smooth import smooth_run
    from experiments.render.progress import Progress
    from slam.smoother import SmootherOptions

    options = SmootherOptions(
        solver=solver.value,
        polish=polish,
        robust=None if robust is Robust.none else robust.value,
        isam2_every=isam2_every,
        marginals=covariances,
    )
    with Progress() as progress:
        summary = smooth_run(run_dir, options, measurements.value, _smoother_progress(progress))
    _echo_smoothed(summary)


def _smooth_graph(path, out, solver, *, polish, robust, every, skip, edge_noise) -> None:
    """`trunkslam smooth GRAPH_FILE`: batch, or iSAM2 fed `every` poses per update."""
    from experiments.pipeline.graph import smooth_graph_file

    if robust is not Robust.none:
        raise typer.BadParameter("not for a graph file (no robust kernel)", param_hint="--robust")
    s = smooth_graph_file(
        path,
        out,
        method="batch" if solver is SmootherSolver.batch else "isam2-chunks",
        chunk_poses=every,
        polish=polish,
        skip=tuple(skip or ()),
        edge_noise=edge_noise.value,
    )
    chi2 = "n/a" if s["chi2_per_dof"] is None else f"{s['chi2_per_dof']:.3f}"
    skipped = "".join(f", {n} {tag} lines skipped" for tag, n in s["skipped"].items())
    typer.echo(
        f"{s['poses']} poses, {s['landmarks']} landmarks, {s['factors']} factors{skipped}; "
        f"{s['method']}: chi2 {s['chi2']:.6g} (initial {s['initial_chi2']:.6g}), chi2/dof "
        f"{chi2} after {s['iterations']} iterations, {s['seconds']:.1f} s -> {s['out']}"
    )


class GraphFormat(StrEnum):  # experiments.pipeline.graph.GRAPH_FORMATS
    g2o = "g2o"


@app.command("export-graph")
@handle_errors
def export_graph_cmd(
    run_dir: Annotated[Path, typer.Argument(help="output folder of `trunkslam slam`")],
    format: Annotated[
        GraphFormat, typer.Option("--format", help="g2o: GTSAM's readG2o conventions")
    ] = GraphFormat.g2o,
    out: Annotated[Path, typer.Option(help="the graph file")] = Path("graph.g2o"),
    measurements: Annotated[
        SmootherMeasurements,
        typer.Option(
            help="ekf: the measurements the filter used; all: also the tentative sightings of "
            "mapped landmarks"
        ),
    ] = SmootherMeasurements.ekf,
) -> None:
    """Write a run's pose-landmark graph (the laser's poses, odometry and range-bearing factors
    with their noise, the associations as run, closures included) as a graph file that GTSAM's
    readG2o, g2o and `trunkslam smooth` read."""
    from experiments.pipeline.graph import export_graph

    g = export_graph(run_dir, out, format.value, measurements.value)
    typer.echo(
        f"{g.poses} poses, {g.landmarks} landmarks, {g.odometry} odometry and {g.measurements} "
        f"bearing-range factors -> {g.path}"
    )
    if g.correlated:
        typer.echo(
            f"note: {g.correlated} measurements have a range-bearing correlation; a BR line "
            "carries none: written with their marginal standard deviations"
        )


class MapFrame(StrEnum):  # experiments.io.map_export.MAP_FRAMES
    local = "local"
    wgs84 = "wgs84"


class MapFormat(StrEnum):  # experiments.pipeline.export_map.MAP_FORMATS
    geojson = "geojson"
    csv = "csv"


@app.command("export-map")
@handle_errors
def export_map_cmd(
    run_dir: Annotated[Path, typer.Argument(help="output folder of `trunkslam slam`")],
    format: Annotated[
        MapFormat, typer.Option("--format", help="geojson (points and ellipse polygons) or csv")
    ] = MapFormat.geojson,
    out: Annotated[
        Path | None, typer.Option(help="the file [default: map.geojson or map_export.csv]")
    ] = None,
    confidence: Annotated[
        float, typer.Option(help="the covariance ellipses' confidence, in (0, 1)")
    ] = 0.95,
    vertices: Annotated[
        int, typer.Option(min=3, max=1000, help="points of each ellipse polygon")
    ] = 36,
    frame: Annotated[
        MapFrame,
        typer.Option(
            help="local: the run's frame, metres; wgs84: longitude and latitude (runs that "
            "started from GPS; about the sequence's gps_origin or --origin)"
        ),
    ] = MapFrame.local,
    origin: Annotated[
        str | None,
        typer.Option(
            help="LAT,LON[,ALT]: the GNSS origin of the run's GPS (degrees, m) for --frame "
            "wgs84 [default: the run's sequence's gps_origin]"
        ),
    ] = None,
    smoothed: Annotated[
        bool, typer.Option(help="the smoother's map (map_smoothed.csv) instead of the EKF's")
    ] = False,
) -> None:
    """Write a run's map for GIS and plotting tools: GeoJSON or CSV with the frame named, each
    landmark's covariance as an ellipse (polygon in GeoJSON, axes in CSV)."""
    from experiments.pipeline.export_map import export_map

    lla = (
        None if origin is None else _numbers("--origin", origin, 3 if origin.count(",") > 1 else 2)
    )
    path = out or Path("map.geojson" if format is MapFormat.geojson else "map_export.csv")
    done = export_map(
        run_dir,
        path,
        format.value,
        confidence=confidence,
        vertices=vertices,
        frame=frame.value,
        origin=lla,
        smoothed=smoothed,
    )
    typer.echo(f"{done['landmarks']} landmarks ({done['map']}, frame {done['frame']}) -> {path}")


def _smoother_progress(progress):
    """The smoother's stages as progress tasks; iSAM2 every 50th update."""

    def report(stage: str, done: int, total: int) -> None:
        if stage != "isam2" or done % 50 == 0 or done == total:
            progress(f"smoother: {stage}", done, total)

    return report


@app.command("export-reference")
@handle_errors
def export_reference_cmd(
    input: Annotated[Path, typer.Argument(help="sequence file (.npz) with GPS or truth")],
    out: Annotated[Path, typer.Option(help="output folder")] = Path("reference"),
) -> None:
    """Write a sequence's GPS track (the fixes inside its scans' time span, the ones a run is
    scored against) and, for simulated runs, the truth as TUM files for evo_ape."""
    from experiments.pipeline.reference import export_reference

    done = export_reference(input, out)
    typer.echo(f"{', '.join(p.name for p in done.files)} -> {out}/")
    if done.n_fixes:
        typer.echo(
            f"{done.n_fixes} fixes; against a run's trajectory_gps_antenna.tum: evo_ape tum "
            f"{out / 'gps.tum'} RUN/trajectory_gps_antenna.tum --sync_method interpolation "
            f"--t_max_diff {done.t_max_diff_s:g}"
        )
    if any(p.name == "truth.tum" for p in done.files):
        typer.echo(
            f"against a run's trajectory.tum (summary.json's truth.rmse_m): evo_ape tum "
            f"{out / 'truth.tum'} RUN/trajectory.tum --sync_method interpolation "
            f"--t_max_diff {done.t_max_diff_s:g}"
        )
    if done.n_fixes >= done.n_scans:  # evo then resamples the GPS at the scans, not the run
        typer.echo(
            f"(more fixes than the {done.n_scans} scans: evo compares each scan with the GPS "
            "interpolated at its time, not each fix with the run; truth.tum is the exact check)"
        )


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
    _emit(format_extract(rows), out)


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
    _emit(format_table(rows), out)


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
    _emit(format_table(rows), out)


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

    sizes = _numbers("--chunks", chunks, len(chunks.split(",")))
    if any(v != int(v) or not 1 <= v <= MAX_CHUNK for v in sizes):
        raise typer.BadParameter(
            f"poses per update must be whole numbers in 1..{MAX_CHUNK}, got {chunks!r}",
            param_hint="--chunks",
        )
    sizes = [int(v) for v in sizes]
    from experiments.render.progress import Progress

    with Progress() as progress:
        rows = bench(data, tuple(sizes), per_pose, seed, progress=progress)
    _emit(format_table(rows), out)


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
    _emit(format_cold(rows), out)


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
            callback=_dask_address,
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
    _emit(format_table(rows, what + (" --quick" if quick else "")), out)


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
    _emit(format_table(rows), out)


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
    _emit(format_table(rows), out)


if __name__ == "__main__":  # pragma: no cover
    app()

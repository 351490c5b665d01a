"""Commands of one SLAM run and what it is exported to: presets, slam, smooth, export-graph,
export-map, export-reference."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from experiments.cli.base import app, check_input, handle_errors, numbers
from experiments.cli.choices import (
    Association,
    EdgeNoise,
    GraphFormat,
    MapFormat,
    MapFrame,
    RerunOption,
    Robust,
    SlamFeatures,
    SmootherMeasurements,
    SmootherSolver,
)
from experiments.render.cli_style import counted


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
    rerun: RerunOption = None,
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
    _before_imports(input, config, dump_config)
    from experiments.io.config_file import config_toml, load_slam_config
    from experiments.pipeline.slam import run_slam_file
    from experiments.render.progress import Progress
    from experiments.render.rerun_sink import rerun_target
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
                rerun_path=rerun_target(rerun),
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


def _before_imports(input: Path | None, config, dump_config: bool) -> None:
    """What `slam` says before its imports (seconds): an input or a --config that is refused
    (a --config's errors first, as ever), else a first run's compile notice."""
    if config is None and not dump_config:
        check_input(input, "sequence file")
    if config is not None:  # a misspelt preset or a missing file
        from experiments.io.config_file import preset_path

        found = preset_path(config)
        if isinstance(found, Path):  # a preset of the package is there by construction
            check_input(found, "config file")
    if input is not None and not dump_config and Path(input).is_file():  # else: its error first
        from experiments.render.cold_start import say_if_cold

        say_if_cold()


def _slam_words(s: dict) -> str:
    """A slam run's summary in one line: scans, landmarks, GPS and truth errors, time, GOSPA."""
    err = _gps_words(s.get("gps")) + _truth_words(s.get("truth"))
    done = f"{counted(s['n_scans'], 'scan')}, {counted(s['landmarks'], 'landmark')}{err}"
    done += f", {s['seconds']:.1f} s" + _compiling_words(s.get("compile_s"))
    if "reference_map" in s:
        g = s["reference_map"]["gospa_20m"]
        done += f", GOSPA {g['distance']:.2f} m (c = 20 m) against the reference map"
    return done


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

    lla = None if origin is None else numbers("--origin", origin, 3 if origin.count(",") > 1 else 2)
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

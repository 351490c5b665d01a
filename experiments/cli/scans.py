"""Commands that make or read sequence files: extract, convert, simulate, simulate-drive."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from experiments.bundled import scene_names  # light: lists the package's scenes for the help
from experiments.cli.base import app, check_input, convert_app, handle_errors, numbers
from experiments.cli.choices import ExtractMethod, LineTest, RerunOption, RosOdometry, Sensor
from experiments.render.cli_style import counted


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
    rerun: RerunOption = None,
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
    check_input(input, "sequence file")
    from experiments.render.cold_start import say_if_cold

    say_if_cold(("features/extract.py",))  # a first run's first line, before the imports
    from experiments.pipeline.extract import run_extract
    from experiments.render.progress import Progress
    from experiments.render.rerun_sink import rerun_target

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
            rerun_path=rerun_target(rerun),
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

    mount = None if laser_pose is None else numbers("--laser-pose", laser_pose, 3)
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
        [numbers("--pose", pose, 3)],
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

"""The `trunkslam` command line. Heavy imports happen inside the commands so `--help` is instant."""

from __future__ import annotations

import functools
import logging
import sys
from pathlib import Path
from typing import Annotated

import typer

app = typer.Typer(
    name="trunkslam",
    help="Tree-trunk features from 2D laser scans, data association and EKF-SLAM.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
convert_app = typer.Typer(help="Convert a dataset into a trunkslam sequence file (.npz).")
bench_app = typer.Typer(help="Benchmarks that print measured figures.")
app.add_typer(convert_app, name="convert")
app.add_typer(bench_app, name="bench")

log = logging.getLogger("trunkslam")


def _fail(msg: str) -> None:
    typer.echo(f"error: {msg}", err=True)
    raise typer.Exit(1)


def handle_errors(fn):
    """The one place that maps our errors (and bad input) to a message and exit code 1."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from experiments.errors import TrunkslamError

        try:
            return fn(*args, **kwargs)
        except (TrunkslamError, ValueError, OSError) as exc:
            _fail(str(exc))

    return wrapper


@app.callback()
def main(verbose: Annotated[bool, typer.Option("--verbose", "-v")] = False) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING, format="%(levelname)s %(message)s"
    )


class _Progress:
    """A progress bar on stderr: redrawn in place on a terminal, a line per quarter otherwise."""

    def __init__(self) -> None:
        self.last = ""
        self.tty = sys.stderr.isatty()

    def __call__(self, desc: str, done: int, total: int) -> None:
        width = 30
        frac = done / max(total, 1)
        if not self.tty:
            step = f"{desc} {int(4 * frac) * 25}%"
            if step != self.last:
                sys.stderr.write(f"{desc}: {done}/{total}\n")
                self.last = step
            return
        filled = int(width * frac)
        line = f"\r{desc:<28} [{'#' * filled}{'.' * (width - filled)}] {done}/{total}"
        if line != self.last:
            sys.stderr.write(line + ("\n" if done >= total else ""))
            sys.stderr.flush()
            self.last = line


@app.command()
@handle_errors
def extract(
    input: Annotated[Path, typer.Argument(help="sequence file (.npz), see datasets/FORMAT.md")],
    out: Annotated[Path, typer.Option(help="features JSON to write")] = Path("features.json"),
    method: Annotated[str, typer.Option(help="paper | geometric | kasa | taubin | bailey")] = (
        "paper"
    ),
    sigma_r: Annotated[
        float | None, typer.Option(help="range noise sigma (m) for paper/geometric")
    ] = None,
    line_test: Annotated[
        str | None, typer.Option(help="lrt (default) | paper (eq. 5); paper/geometric only")
    ] = None,
    rerun: Annotated[Path | None, typer.Option(help="also write a rerun recording")] = None,
) -> None:
    """Extract circles, lines, edges and clutter from every scan of a sequence file."""
    from dataclasses import asdict

    from experiments.export import FEATURES_SCHEMA, dumps_json, features_to_dict, write_atomic
    from experiments.sequence import load_sequence
    from experiments.viz import open_recording
    from features import extract_features
    from features.bailey import BaileyParams
    from features.extract import ExtractorParams

    params: dict = {}
    if line_test is not None:
        params["line_test"] = line_test
    if sigma_r is not None:
        params["sigma_r_m"] = sigma_r
    if method == "bailey":
        if params:
            raise ValueError("--sigma-r and --line-test do not apply to --method bailey")
        resolved = asdict(BaileyParams())
    else:
        resolved = ExtractorParams.from_kwargs(**params).to_dict()
    if out.parent and not out.parent.is_dir():
        raise ValueError(f"--out: folder {out.parent} does not exist")
    seq = load_sequence(input)
    rec = open_recording(rerun)
    progress = _Progress()
    scans = []
    for k in range(seq.n_scans):
        scan = seq.scan(k)
        f = extract_features(scan, method, **params)
        scans.append(features_to_dict(f, k))
        rec.set_scan(k)
        rec.log_scan(scan)
        rec.log_features(scan, f)
        if k % 50 == 0 or k == seq.n_scans - 1:
            progress("extract", k + 1, seq.n_scans)
    rec.close()
    doc = {
        "schema": FEATURES_SCHEMA,
        "input": str(input),
        "method": method,
        "params": resolved,
        "frame": "laser",
        "scans": scans,
    }
    write_atomic(out, dumps_json(doc))
    n_c = sum(len(s["circles"]) for s in scans)
    typer.echo(f"{seq.n_scans} scans -> {out} ({n_c} circles)")


@convert_app.command("victoria-park")
@handle_errors
def convert_victoria_park(
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("vp.npz"),
    data: Annotated[
        Path | None, typer.Option(help="victoria_park folder (default: $TRUNKSLAM_DATA/...)")
    ] = None,
) -> None:
    """Victoria Park (odometry, GPS, the 2000 raw scans) as one sequence file."""
    from experiments.sequence import save_sequence
    from experiments.victoria_park import load_victoria_park

    seq = load_victoria_park(data)
    save_sequence(seq, out)
    typer.echo(f"{seq.n_scans} scans -> {out}")


@app.command()
@handle_errors
def simulate(
    scene: Annotated[str, typer.Argument(help="scene name in datasets/scenes, or a JSON path")],
    pose: Annotated[str, typer.Option(help="x,y,theta of the sensor in the world (m, m, rad)")],
    out: Annotated[Path, typer.Option(help="sequence file to write")] = Path("scan.npz"),
    sensor: Annotated[str, typer.Option(help="pls200 | lms200")] = "pls200",
    back_to_back: Annotated[bool, typer.Option(help="two sensors back to back (360 deg)")] = False,
    noise: Annotated[float | None, typer.Option(help="range noise sigma (m)")] = None,
    seed: Annotated[int, typer.Option(min=0)] = 0,
) -> None:
    """Simulate one scan of a scene from a pose and write it as a sequence file."""
    import numpy as np

    from experiments.sequence import save_sequence
    from experiments.sim import simulate_to_sequence

    try:
        xyz = np.array([float(v) for v in pose.split(",")])
    except ValueError:
        xyz = np.array([])
    if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
        raise ValueError(f"--pose: expected three numbers x,y,theta, got {pose!r}")
    seq = simulate_to_sequence(
        scene,
        xyz[None, :],
        sensor_name=sensor,
        back_to_back=back_to_back,
        noise_m=noise,
        seed=seed,
    )
    save_sequence(seq, out)
    typer.echo(f"1 scan of {scene} -> {out}")


@app.command()
@handle_errors
def reproduce(
    names: Annotated[
        list[str] | None, typer.Argument(help="experiments to run (default: all)")
    ] = None,
    quick: Annotated[bool, typer.Option(help="small-sample version")] = False,
    out: Annotated[Path, typer.Option(help="output folder")] = Path("results"),
    seed: Annotated[int, typer.Option(help="root random seed", min=0)] = 0,
) -> None:
    """Run the paper's experiments: tables (.md/.csv), figures (.png), recordings (.rrd)."""
    from experiments.reproduce import run_experiments

    written = run_experiments(names or [], out, quick=quick, seed=seed, progress=_Progress())
    typer.echo(f"{len(written)} files in {out}/ (see {out}/manifest.json)")


@bench_app.command("extract")
@handle_errors
def bench_extract(
    repeats: Annotated[int, typer.Option(help="passes over the 2000 scans")] = 3,
    data: Annotated[Path | None, typer.Option(help="victoria_park folder")] = None,
) -> None:
    """Scans per second of each extractor on the 2000 real Victoria Park scans."""
    from experiments.bench import bench_extract as run
    from experiments.bench import format_extract

    typer.echo(format_extract(run(repeats=repeats, root=data)))


@bench_app.command("association")
@handle_errors
def bench_association(
    repeats: Annotated[int, typer.Option(help="scans timed per method")] = 200,
    seed: Annotated[int, typer.Option(min=0)] = 0,
) -> None:
    """Median time per scan of each association method at Victoria Park scale."""
    from experiments.bench_association import bench, format_table

    typer.echo(format_table(bench(repeats=repeats, seed=seed)))


@app.command("slam")
@handle_errors
def slam_cmd(
    input: Annotated[Path, typer.Argument(help="sequence file (.npz), see datasets/FORMAT.md")],
    features: Annotated[str, typer.Option(help="paper | geometric | bailey")] = "paper",
    association: Annotated[str, typer.Option(help="ihgr | jcbb | nn")] = "ihgr",
    out: Annotated[Path, typer.Option(help="output folder")] = Path("slam_out"),
    rerun: Annotated[Path | None, typer.Option(help="also write a rerun recording")] = None,
    initial_heading: Annotated[
        float | None, typer.Option(help="start heading (rad) when starting from GPS")
    ] = None,
) -> None:
    """EKF-SLAM over a sequence: trajectory (TUM and CSV with covariance), map, summary."""
    from experiments.exp_slam import slam_command

    s = slam_command(input, features, association, out, rerun, initial_heading)
    typer.echo(f"{s['n_scans']} scans, {s['landmarks']} landmarks, {s['seconds']:.1f} s -> {out}/")


@bench_app.command("slam")
@handle_errors
def bench_slam(
    trees: Annotated[int, typer.Option(help="trees along the avenue (the final map size)")] = 800,
    association: Annotated[str, typer.Option(help="ihgr | jcbb | nn")] = "ihgr",
    seed: Annotated[int, typer.Option(min=0)] = 0,
) -> None:
    """EKF-SLAM time per scan against the size of the map."""
    from experiments.bench_slam import bench, format_table

    typer.echo(format_table(bench(n_trees=trees, association=association, seed=seed)))


if __name__ == "__main__":  # pragma: no cover
    app()

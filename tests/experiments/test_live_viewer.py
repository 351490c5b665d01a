"""`--rerun spawn|connect[=ADDR]`: a run streamed live to a rerun viewer, headless.

The viewer is rerun's own program run without a window (`rerun --port P --save FILE`: it
listens for SDKs as a viewer does and writes what arrives to FILE), so what arrived is read back
with the SDK's reader and compared with the file recording of the same run. `spawn` would open a
window: its one call into rerun (`viz._spawn`) is replaced by a connection to that sink."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from support import read_recording, recording_rows
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import ConfigError
from experiments.io.sequence_file import save_sequence
from experiments.pipeline.slam import run_slam_file
from experiments.render import rerun_sink, viz
from experiments.render.rerun_sink import (
    DEFAULT_PORT,
    Viewer,
    parse_rerun_target,
    rerun_target,
    viewer_program,
)
from experiments.sim import CycabParams, simulate_cycab_run
from slam import SlamConfig

runner = CliRunner()
CFG = SlamConfig().with_(**{"features.method": "geometric", "association.method": "ihgr"})
# wall times: differ between any two runs
WALL_TIME_SERIES = ("series/ms_per_scan",)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Sink:
    """`rerun --port PORT --save FILE`: a viewer's gRPC server without a window."""

    def __init__(self, file: Path):
        self.file = file
        self.port = _free_port()
        env = {**os.environ, "RERUN_APP_ONLY": "true"}  # no analytics banner
        self.proc = subprocess.Popen(
            [viewer_program(), "--port", str(self.port), "--save", str(file)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return
            except OSError:
                time.sleep(0.1)
        self.stop()
        raise AssertionError("the rerun sink did not start listening")

    def stop(self) -> None:
        """End the sink (its own process group: `.venv/bin/rerun` is a wrapper that starts
        rerun's binary as a child), and wait until every process of it has ended; its file then
        holds what arrived."""
        for sig in (signal.SIGTERM, signal.SIGKILL):
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                break
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                self.proc.poll()  # (reaps the wrapper once it ends)
                try:
                    os.killpg(self.proc.pid, 0)
                except ProcessLookupError:
                    return
                time.sleep(0.1)
        self.proc.wait()

    def received(self) -> Path:
        """End the sink, and what it received as a file the SDK's reader reads (the sink's own
        file has no footer: `rerun rrd merge` writes one)."""
        self.stop()
        readable = self.file.with_suffix(".read.rrd")
        subprocess.run(
            [viewer_program(), "rrd", "merge", str(self.file), "-o", str(readable)],
            check=True,
            capture_output=True,
        )
        return readable


@pytest.fixture
def sink(tmp_path):
    s = Sink(tmp_path / "arrived.rrd")
    yield s
    s.stop()


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("live")
    seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=25))
    return save_sequence(seq, tmp / "run.npz")


# ---- the option's values -------------------------------------------------------------------


def test_targets_are_read_as_rerun_writes_them():
    assert parse_rerun_target("run.rrd") == Path("run.rrd")
    assert parse_rerun_target("./spawn") == Path("spawn")  # a file named spawn
    assert parse_rerun_target(None) is None
    spawn = parse_rerun_target("spawn")
    assert (spawn.mode, spawn.port) == ("spawn", DEFAULT_PORT)
    default = f"rerun+http://127.0.0.1:{DEFAULT_PORT}/proxy"
    assert parse_rerun_target("connect").url == default
    for given, url in [
        ("connect=10.1.2.3:9000", "rerun+http://10.1.2.3:9000/proxy"),
        ("connect=9000", "rerun+http://127.0.0.1:9000/proxy"),
        ("connect=viewer.local", f"rerun+http://viewer.local:{DEFAULT_PORT}/proxy"),
        ("connect=rerun+http://h:1234/proxy", "rerun+http://h:1234/proxy"),
        ("connect=rerun+https://h/proxy", "rerun+https://h:443/proxy"),
        ("connect=[::1]:9000", "rerun+http://[::1]:9000/proxy"),
    ]:
        v = parse_rerun_target(given)
        assert (v.mode, v.url, v.given) == ("connect", url, given)


@pytest.mark.parametrize(
    ("given", "why"),
    [
        ("connect=", "no address"),
        ("connect=http://h:1/proxy", "scheme 'http'"),
        ("connect=rerun+http://h:1/other", "/proxy"),
        ("connect=h:99999", "not a viewer address"),
        ("connect=h:abc", "not a viewer address"),
        ("connect=h:0", "port 0"),
        ("connect=:9000", "no host"),
        ("spawn=9000", "not a viewer target"),
        ("rerun+http://h:1/proxy", "not a viewer target"),
    ],
)
def test_malformed_addresses_are_refused_by_name(given, why):
    with pytest.raises(ConfigError, match=why) as err:
        parse_rerun_target(given)
    assert str(err.value).startswith(f"--rerun {given}:")


def test_an_address_nobody_answers_is_refused_before_the_run(run_file, tmp_path):
    with pytest.raises(ConfigError, match="no rerun viewer answers at 127.0.0.1:1 "):
        rerun_target("connect=127.0.0.1:1")
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run_file), "--out", str(out), "--rerun", "connect=1"])
    assert res.exit_code == 1
    assert res.output.startswith("error: --rerun connect=1: no rerun viewer answers at 127.0.0.1:1")
    assert not out.exists()  # refused before the run: nothing written
    res = runner.invoke(
        app, ["extract", str(run_file), "--out", str(tmp_path / "f.json"), "--rerun", "connect=:1"]
    )
    assert res.exit_code == 1 and "error: --rerun connect=:1: no host" in res.output
    assert not (tmp_path / "f.json").exists()


def test_spawn_without_a_display_is_refused_before_the_run(monkeypatch):
    monkeypatch.setattr(rerun_sink.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(rerun_sink, "_port_open", lambda viewer: False)
    with pytest.raises(ConfigError, match="--rerun spawn: no display here"):
        rerun_target("spawn")
    monkeypatch.setattr(rerun_sink, "viewer_program", lambda: None)
    with pytest.raises(ConfigError, match="--rerun spawn: the rerun viewer program"):
        rerun_target("spawn")


# ---- streaming -----------------------------------------------------------------------------


def test_a_run_streamed_to_a_viewer_holds_what_its_file_holds(run_file, sink, tmp_path):
    """connect=127.0.0.1:PORT: the sink receives the recording the file would hold, row for row
    (the wall-time series aside), with its layout."""
    run_slam_file(run_file, CFG, tmp_path / "a", rerun_path=tmp_path / "file.rrd")
    live = rerun_target(f"connect=127.0.0.1:{sink.port}")
    run_slam_file(run_file, CFG, tmp_path / "b", rerun_path=live)
    got = sink.received()
    assert not (tmp_path / "b" / "file.rrd").exists()
    arrived = recording_rows(got, WALL_TIME_SERIES)
    written = recording_rows(tmp_path / "file.rrd", WALL_TIME_SERIES)
    assert arrived.keys() == written.keys()
    assert {"/world/vehicle", "/world/landmarks", "/series/nis"} <= arrived.keys()
    assert arrived == written
    a, w = read_recording(got), read_recording(tmp_path / "file.rrd")
    assert a["timelines"] >= {"scan", "time"}
    assert sorted(a["views"]) == sorted(w["views"]) and len(a["views"]) >= 8


def test_spawn_streams_to_the_viewer_it_starts(run_file, sink, tmp_path, monkeypatch):
    """`slam --rerun spawn`: the viewer is started once, on rerun's port, with the recording's
    layout, and the run streams to it (here: the spawn is a connection to the sink)."""
    calls = []

    def fake_spawn(rec, viewer, layout):
        calls.append((viewer, layout))
        rec.connect_grpc(f"rerun+http://127.0.0.1:{sink.port}/proxy", default_blueprint=layout)

    monkeypatch.setattr(viz, "_spawn", fake_spawn)
    monkeypatch.setenv("DISPLAY", ":0")
    out = tmp_path / "out"
    res = runner.invoke(app, ["slam", str(run_file), "--out", str(out), "--rerun", "spawn"])
    assert res.exit_code == 0, res.output
    got = read_recording(sink.received())
    assert len(calls) == 1
    viewer, layout = calls[0]
    assert isinstance(viewer, Viewer) and (viewer.mode, viewer.port) == ("spawn", DEFAULT_PORT)
    assert "world/vehicle" in got["entities"]
    assert (out / "summary.json").is_file() and not list(out.glob("*.rrd"))


def test_extract_streams_to_a_viewer(run_file, sink, tmp_path):
    res = runner.invoke(
        app,
        ["extract", str(run_file), "--out", str(tmp_path / "f.json"), "--method", "geometric"]
        + ["--rerun", f"connect=127.0.0.1:{sink.port}"],
    )
    assert res.exit_code == 0, res.output
    got = read_recording(sink.received())
    assert {"laser/scan", "laser/features/circles", "series/circles_per_scan"} <= got["entities"]
    assert [v[1] for v in got["views"] if v[0] == "2D"] == ["laser/y_up"]


def test_ellipses_drawn_at_once_are_those_drawn_one_by_one():
    """The recording draws every landmark's ellipse each scan with one call; each outline is
    the 2.4477-sigma (95%) ellipse numpy's eigh gives for its matrix (the same points,
    whichever end of the axes eigh's signs start from)."""
    from experiments.render.shapes import ellipse_polyline, ellipse_polylines

    rng = np.random.default_rng(0)
    centers = rng.normal(size=(30, 2)) * 50
    a = rng.normal(size=(30, 2, 2))
    covs = a @ a.transpose(0, 2, 1)
    covs[0] = [[1.0, 0.0], [0.0, 0.0]]  # degenerate: a segment
    one_by_one = np.array([ellipse_polyline(c, p) for c, p in zip(centers, covs)])
    assert np.array_equal(ellipse_polylines(centers, covs), one_by_one)
    drawn = ellipse_polylines(centers, covs)
    for c, p, line in zip(centers, covs, drawn):
        w, v = np.linalg.eigh(p)
        axes = v * (2.4477 * np.sqrt(np.clip(w, 0.0, None)))  # columns: the two semi-axes
        # each drawn point is c + axes @ (cos t, sin t) for some t: the unit circle back
        u = np.linalg.lstsq(axes, (line - c).T, rcond=None)[0] if w[0] > 1e-12 else None
        if u is not None:
            np.testing.assert_allclose(np.hypot(*u), 1.0, atol=1e-9)
        else:  # the degenerate matrix: a segment along its one axis
            np.testing.assert_allclose(np.abs(line - c).max(axis=0), np.abs(axes[:, 1]), atol=1e-9)
    assert ellipse_polylines(np.zeros((0, 2)), np.zeros((0, 2, 2))).shape == (0, 41, 2)


def test_bench_slam_row_of_a_recorded_run(run_file, monkeypatch):
    """`bench slam`'s recorded row: the run recorded as `slam --rerun FILE` records it, and the
    medians over pairs (plain run, recorded run) of the recorded run's wall and CPU seconds over
    the plain run's ("recording ratio", "recording CPU ratio"), and the file's size. The clocks
    are scripted: each run takes the seconds given."""
    from experiments.bench import slam as bench_slam
    from experiments.io.sequence_file import load_sequence

    # (plain, recorded) wall and CPU seconds of three pairs: wall ratios 2, 1.25, 1.5; CPU 3, 1, 2
    walls = iter([1.0, 2.0, 4.0, 5.0, 2.0, 3.0])
    cpus = iter([1.0, 3.0, 2.0, 2.0, 1.0, 2.0])

    def clock(seconds):
        now = [0.0, 0]

        def read():  # each run reads its clock twice: start and end
            now[1] += 1
            if now[1] % 2 == 0:
                now[0] += next(seconds)
            return now[0]

        return read

    fake = type("T", (), {"perf_counter": clock(walls), "process_time": clock(cpus)})
    monkeypatch.setattr(bench_slam, "time", fake)
    seq = load_sequence(run_file)
    row = bench_slam.recorded_row(seq, CFG, bench_slam.BINS, None, pairs=3)
    assert row["map size"] == "whole run (Victoria Park, with a recording)"
    assert row["scans"] == seq.n_scans
    assert row["recording ratio"] == 1.5
    assert row["recording CPU ratio"] == 2.0
    assert row["run seconds"] == 3.0  # the recorded runs' median
    assert 0 < row["recording MiB"] < 50
    assert re.fullmatch(r"\d+\.\d-\d+\.\d", row["load"])


def test_the_path_is_a_trail_of_pieces_that_make_the_whole_path(run_file, tmp_path):
    """world/path is logged a piece a scan (its points since the last scan), and both map
    views draw every piece up to the time cursor (a visible time range on the entity, for
    both timelines): the path so far, as when the whole path was logged at each scan."""
    from rerun.chunk import RrdReader

    run_slam_file(run_file, CFG, tmp_path / "o", rerun_path=tmp_path / "r.rrd")
    reader = RrdReader(tmp_path / "r.rrd")
    pieces = {}
    for chunk in reader.store().stream().to_chunks():
        if str(chunk.entity_path) == "/world/path":
            d = chunk.to_record_batch().to_pydict()
            for k, strips in zip(d["scan"], d["LineStrips2D:strips"]):
                pieces[k] = np.array(strips[0])
    traj = np.loadtxt(tmp_path / "o" / "trajectory.tum")[:, 1:3]
    assert sorted(pieces) == list(range(len(traj)))
    assert len(pieces[0]) == 1 and all(len(pieces[k]) == 2 for k in range(1, len(traj)))
    for k in range(1, len(traj)):
        assert np.array_equal(pieces[k][0], pieces[k - 1][-1])  # the pieces join
    whole = np.array([pieces[0][0]] + [pieces[k][1] for k in range(1, len(traj))])
    assert np.allclose(whole, traj, atol=1e-4)  # float32 in the recording
    trails = {}
    for store in reader.blueprints():
        for chunk in reader.store(store=store).stream().to_chunks():
            path = str(chunk.entity_path)
            d = chunk.to_record_batch().to_pydict()
            if "VisibleTimeRanges:ranges" in d:
                entity = path.split("/overrides/")[1].removesuffix("/visualizers")
                trails.setdefault(entity, []).append(d["VisibleTimeRanges:ranges"][-1])
    assert set(trails) == {"world/path", "world/truth/path"}
    for ranges in trails["world/path"]:
        assert {r["timeline"] for r in ranges} == {"scan", "time"}
        for r in ranges:  # from the start (infinite: a null) to the cursor (relative 0)
            assert r["range"] == {"start": None, "end": 0}
    assert len(trails["world/path"]) == 2  # both map views


class _Tee:
    """A visualiser that hands every call to each of `recorders` (one run, several files)."""

    def __init__(self, *recorders):
        self.recorders = recorders

    def __getattr__(self, name):
        def each(*args, **kwargs):
            for r in self.recorders:
                getattr(r, name)(*args, **kwargs)

        return each


@pytest.mark.parametrize("batch", [3, 64])
def test_batched_rows_are_the_rows_logged_one_by_one(batch, tmp_path):
    """The scene sent a batch of scans at a time (`send_columns`) holds exactly the rows that
    logging each as it comes (`rr.log`, batch_scans=1) holds, at the same scans and times."""
    from experiments.eval.series import slam_panels, slam_series
    from slam import run_slam

    seq = simulate_cycab_run(np.random.default_rng(5), "tree_park", CycabParams(n_scans=30))
    one = viz.Recorder(tmp_path / "one.rrd", series=slam_panels(True), batch_scans=1)
    many = viz.Recorder(tmp_path / "many.rrd", series=slam_panels(True), batch_scans=batch)
    assert one._batch.one_by_one and not many._batch.one_by_one
    rec = _Tee(one, many)
    rec.log_truth_trees(seq.truth_landmarks)
    lg = run_slam(seq, CFG, visualiser=rec)
    rec.log_series(lg.scan_t, slam_series(lg, seq.truth_t, seq.truth_pose))
    rec.close()
    a, b = recording_rows(tmp_path / "one.rrd"), recording_rows(tmp_path / "many.rrd")
    assert a.keys() == b.keys() and len(a["/world/landmarks"]) == seq.n_scans
    assert a == b

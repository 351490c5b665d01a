"""Results that survive interruption: the output folder of `trunkslam reproduce` and `trunkslam
slam`, and every recording, is either the old complete set or the new complete set, never a mix,
after a Ctrl-C (SIGINT to a real subprocess, at several points) or a write error (a full disk,
injected where every result file is flushed)."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from subprocesses import start, trunkslam
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.io.outputs import check_output_folder, check_outputs
from experiments.io.writers import atomic_folder, write_atomic
from tests.support import leftovers, read_recording, snapshot

runner = CliRunner()
FAST = ["noise-calibration"]  # a quick experiment: two tables
# in this process: a pool of worker processes (each importing the project and loading the
# kernels, about 15 s of CPU a run) is not what these tests are about
ONE_WORKER = ["--workers", "1"]


def assert_complete_reproduce_set(folder: Path, seed: int) -> None:
    """A complete result set of one run: its manifest has the seed and lists exactly the files
    beside it."""
    m = json.loads((folder / "manifest.json").read_text())
    assert m["seed"] == seed
    files = set(snapshot(folder)) - {"manifest.json"}
    assert files == set(m["outputs"]), files ^ set(m["outputs"])
    assert m["failed"] == {}


def assert_old_or_new(folder: Path, old: dict[str, str], new_seed: int) -> str:
    now = snapshot(folder)
    if now == old:
        return "old"
    assert_complete_reproduce_set(folder, new_seed)
    return "new"


@pytest.fixture(scope="module")
def old_set(noise_calibration_set):
    """A complete `reproduce noise-calibration --quick --seed 0` result set (made once a session,
    tests/conftest.py; each test copies it)."""
    assert FAST == ["noise-calibration"]  # the experiment of the shared set
    assert_complete_reproduce_set(noise_calibration_set, 0)
    return noise_calibration_set


def copy_of(folder: Path, dest: Path) -> Path:
    import shutil

    shutil.copytree(folder, dest)
    return dest


# ---- the writers themselves ---------------------------------------------------------------------


def test_atomic_folder_replaces_the_whole_set_or_nothing(tmp_path):
    target = tmp_path / "set"
    with atomic_folder(target) as stage:
        (stage / "a.txt").write_text("old a")
        (stage / "b.txt").write_text("old b")
    old = snapshot(target)
    with pytest.raises(RuntimeError), atomic_folder(target) as stage:
        (stage / "a.txt").write_text("new a")
        raise RuntimeError("interrupted half way")
    assert snapshot(target) == old and not leftovers(target)
    with atomic_folder(target) as stage:
        (stage / "c.txt").write_text("new c")
    assert snapshot(target) == {"c.txt": hashlib.sha256(b"new c").hexdigest()}
    assert not leftovers(target)
    assert target.stat().st_mode & 0o777 == 0o755


def test_a_killed_runs_temporary_folder_is_cleaned_up_by_the_next_run(tmp_path):
    target = tmp_path / "set"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".set.partial-{dead.pid}-abc"
    stale.mkdir()
    alive = tmp_path / f".set.partial-{os.getpid()}-xyz"  # a running process's: left alone
    alive.mkdir()
    with atomic_folder(target) as stage:
        (stage / "x").write_text("x")
    assert not stale.exists() and alive.exists()


def test_output_checks_refuse_inputs_and_non_regular_paths(tmp_path):
    inp = tmp_path / "in.npz"
    inp.write_bytes(b"data")
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "elsewhere.json")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    cases = [
        (inp, "is an input"),
        (tmp_path / "." / "in.npz", "is an input"),
        (link, "symbolic link"),
        (fifo, "FIFO"),
        (tmp_path, "folder"),
        (Path("/dev/null"), "device"),
        (tmp_path / "missing" / "x.json", "does not exist"),
    ]
    for path, words in cases:
        with pytest.raises(DataError, match=words) as info:
            check_outputs("extract", inputs=[inp], files={"--out": path})
        assert "--out" in str(info.value)
    hard = tmp_path / "hard.npz"
    os.link(inp, hard)  # another name of the same file
    with pytest.raises(DataError, match="is an input"):
        check_outputs("extract", inputs=[inp], files={"--out": hard})
    with pytest.raises(DataError, match="symbolic link"):
        write_atomic(link, "x")
    assert not (tmp_path / "elsewhere.json").exists()
    assert inp.read_bytes() == b"data"

    ours = tmp_path / "ours"
    ours.mkdir()
    (ours / "t.csv").write_text("1")
    (ours / "manifest.json").write_text('{"command": "trunkslam sweep", "outputs": ["t.csv"]}')
    check_output_folder(ours, "--out", "sweep")  # an earlier result set: fine
    check_output_folder(tmp_path / "new", "--out", "sweep")  # absent: fine
    foreign = tmp_path / "home"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("years of work")
    with pytest.raises(DataError, match="no manifest.json"):
        check_output_folder(foreign, "--out", "sweep")
    with pytest.raises(DataError, match="holds the input"):
        check_outputs("sweep", inputs=[inp], folders={"--out": tmp_path})
    with pytest.raises(DataError, match="not a folder"):
        check_output_folder(inp, "--out", "sweep")


def test_reproduce_refuses_a_folder_that_is_not_a_result_set(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    res = runner.invoke(app, ["reproduce", "noise-calibration", "--quick", "--out", str(tmp_path)])
    assert res.exit_code == 1 and "no manifest.json" in res.output
    assert (tmp_path / "notes.txt").read_text() == "mine"


# ---- a full disk: a write error injected where every result file is flushed ---------------------


def _fail_fsync_at(monkeypatch, n: int) -> list[int]:
    """os.fsync raises ENOSPC ("No space left on device") on its n-th call (1-based)."""
    calls = [0]
    real = os.fsync

    def fsync(fd):
        calls[0] += 1
        if calls[0] == n:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    return calls


@pytest.mark.slow
def test_reproduce_under_a_full_disk_keeps_the_old_set(old_set, tmp_path, monkeypatch):
    """A write error at the first table, in the middle, at the manifest (the last write): exit 1
    naming the error, and the folder is still the old complete set."""
    out = copy_of(old_set, tmp_path / "results")
    old = snapshot(out)
    n_writes = len(old)  # one flushed write per file of the set (the manifest included)
    for n in (1, n_writes // 2, n_writes):
        _fail_fsync_at(monkeypatch, n)
        res = runner.invoke(
            app, ["reproduce", *FAST, *ONE_WORKER, "--quick", "--seed", "1", "--out", str(out)]
        )
        monkeypatch.undo()
        assert res.exit_code == 1, (n, res.output)
        assert "No space left on device" in res.output
        assert snapshot(out) == old, n
        assert not leftovers(out), leftovers(out)
    res = runner.invoke(
        app, ["reproduce", *FAST, *ONE_WORKER, "--quick", "--seed", "1", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert_complete_reproduce_set(out, 1)
    assert snapshot(out) != old


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    path = tmp_path_factory.mktemp("drive") / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "40", "--seed", "3", "--out", str(path)])
    assert res.exit_code == 0, res.output
    return path


@pytest.mark.slow
def test_slam_under_a_full_disk_keeps_the_old_outputs(drive, tmp_path, monkeypatch):
    out = tmp_path / "slam_out"
    rrd = out / "run.rrd"
    res = runner.invoke(app, ["slam", str(drive), "--out", str(out), "--rerun", str(rrd)])
    assert res.exit_code == 0, res.output
    old = snapshot(out)
    assert {"trajectory.tum", "summary.json", "map.csv", "run.rrd"} <= set(old)
    for n in (1, 4, 9):  # the recording, trajectory.csv, manifest.json (the last)
        _fail_fsync_at(monkeypatch, n)
        res = runner.invoke(
            app,
            ["slam", str(drive), "--features", "geometric", "--out", str(out), "--rerun", str(rrd)],
        )
        monkeypatch.undo()
        assert res.exit_code == 1 and "No space left" in res.output, (n, res.output)
        assert snapshot(out) == old, n
        assert not leftovers(out)
    res = runner.invoke(app, ["slam", str(drive), "--features", "geometric", "--out", str(out)])
    assert res.exit_code == 0, res.output
    new = snapshot(out)
    assert json.loads((out / "summary.json").read_text())["features"] == "geometric"
    assert "run.rrd" not in new  # the set is this run's files only
    assert new["trajectory.tum"] != old["trajectory.tum"]


# ---- Ctrl-C: a real subprocess sent SIGINT at several points ------------------------------------


def _interrupt_when(proc: subprocess.Popen, ready, timeout: float = 120.0) -> bool:
    """Send SIGINT once ready() is true; returns False if the process ended first."""
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < timeout:
        if ready():
            proc.send_signal(signal.SIGINT)
            return True
        time.sleep(0.005)
    return False


def _staged(out: Path, min_files: int):
    """True once the run's temporary folder beside `out` holds at least min_files files."""

    def ready() -> bool:
        for stage in out.parent.glob(f".{out.name}.partial-*"):
            if sum(1 for p in stage.rglob("*") if p.is_file()) >= min_files:
                return True
        return False

    return ready


@pytest.mark.slow
def test_reproduce_interrupted_at_several_points_is_old_or_new(old_set, tmp_path):
    """SIGINT during start-up, as soon as the temporary folder exists, after the first table,
    and after every file but the manifest: each time the folder is the old set or the new
    complete set (when the signal came too late), and no temporary folder is left."""
    out = copy_of(old_set, tmp_path / "results")
    old = snapshot(out)
    points = {
        "start-up": lambda: True,
        "temporary folder created": _staged(out, 0),
        "first table written": _staged(out, 1),
        "all but the manifest": _staged(out, len(old) - 1),
    }
    interrupted = 0
    for name, ready in points.items():
        args = ["reproduce", *FAST, "--quick", "--seed", "1", "--out", str(out)]
        proc = start(args, tmp_path, dict(os.environ, PYTHONUNBUFFERED="1"))
        sent = _interrupt_when(proc, ready)
        _, err = proc.communicate(timeout=120)
        assert "Traceback" not in err or "KeyboardInterrupt" in err, err
        state = assert_old_or_new(out, old, new_seed=1)
        if sent and proc.returncode != 0:
            interrupted += 1
            assert state == "old", name
        assert not leftovers(out), (name, leftovers(out))
        if state == "new":
            old = snapshot(out)  # later points compare with this set
    assert interrupted >= 2  # most points were hit while the run was still going


def _run_interrupted_at(point: str, args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run trunkslam with a SIGINT raised at the named `interruption_point` (deterministic)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", TRUNKSLAM_INTERRUPT_AT=point)
    return trunkslam(args, cwd, env)


@pytest.mark.slow
def test_slam_and_extract_interrupted_leave_old_outputs_and_no_truncated_recording(drive, tmp_path):
    """Ctrl-C once the first result file is in the temporary folder, and in the middle of the
    recording: the old outputs stay, nothing temporary is left."""
    out = tmp_path / "slam_out"
    res = runner.invoke(app, ["slam", str(drive), "--out", str(out)])
    assert res.exit_code == 0, res.output
    old = snapshot(out)
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"an older recording")
    drive_sum = hashlib.sha256(drive.read_bytes()).hexdigest()
    args = ["slam", str(drive), "--features", "bailey", "--out", str(out), "--rerun", str(rrd)]
    # mid-recording: the old recording and the old folder stay
    proc = _run_interrupted_at("recording-scan", args, tmp_path)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert snapshot(out) == old and rrd.read_bytes() == b"an older recording"
    assert not leftovers(out) and not list(tmp_path.glob(".run.rrd.*"))
    # first result file staged: the folder stays old; the recording, closed and renamed into
    # place before the folder is written (README: not part of the atomic set), is the new one
    proc = _run_interrupted_at("file-written", args, tmp_path)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert snapshot(out) == old
    assert "series/map_size" in read_recording(rrd)["entities"]
    assert not leftovers(out) and not list(tmp_path.glob(".run.rrd.*"))
    rrd.write_bytes(b"an older recording")
    features = tmp_path / "f.json"
    features.write_text("{}")
    args = ["extract", str(drive), "--out", str(features), "--rerun", str(rrd)]
    proc = _run_interrupted_at("recording-scan", args, tmp_path)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert features.read_text() == "{}" and rrd.read_bytes() == b"an older recording"
    assert not list(tmp_path.glob(".*"))
    assert hashlib.sha256(drive.read_bytes()).hexdigest() == drive_sum

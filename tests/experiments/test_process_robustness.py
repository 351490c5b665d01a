"""Two commands on one result folder, killed runs, signals (issue 29), with real processes.

- A result folder is held by one command at a time (`lock_folder`: an advisory lock on
  `.NAME.lock` beside it): a second command is refused at once, naming the holder; a killed
  holder's lock goes with it. 100 randomly timed concurrent pairs (slam/smooth, slam/reproduce)
  on one folder leave no mixed result set.
- Worker processes die with their parent: `kill -9` of `reproduce --workers 2` or `sweep`
  leaves no process behind (found by a marker in their environment).
- SIGTERM and SIGHUP clean up as Ctrl-C does (exit 1, old outputs kept, nothing temporary left);
  a SIGHUP the caller ignores (nohup) stays ignored. The signals come from the fault-injection
  points (`TRUNKSLAM_INTERRUPT_AT`, `TRUNKSLAM_INTERRUPT_SIGNAL`), and once from outside when the
  run's temporary folder appears, as `timeout` would send it.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from subprocesses import default_signals, error_line, marked_env, marked_processes, start, trunkslam
from support import invoke, leftovers, snapshot

from experiments.io.outputs import MANIFEST, lock_folder

TESTS = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Drives of 10 and 14 scans and an earlier `slam` output of the first: copy them."""
    d = tmp_path_factory.mktemp("processes")
    invoke("simulate-drive", "--scans", "10", "--seed", "3", "--out", d / "a.npz")
    invoke("simulate-drive", "--scans", "14", "--seed", "4", "--out", d / "b.npz")
    invoke("slam", d / "a.npz", "--out", d / "prev")
    return d


def wait_for(condition, timeout: float, what: str, step: float = 0.02):
    """Poll `condition` until it returns something true; fail after `timeout` seconds."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        got = condition()
        if got:
            return got
        time.sleep(step)
    pytest.fail(f"timed out after {timeout} s waiting for {what}")


# ---- one command per result folder ------------------------------------------------------------


@pytest.mark.slow
def test_a_held_folder_refuses_a_second_command_naming_the_holder(made, tmp_path):
    out = shutil.copytree(made / "prev", tmp_path / "out")
    old = snapshot(out)
    with lock_folder(out, "--out"):
        with lock_folder(out, "--out"):  # the same process again: fine (slam --smooth)
            pass
        for args in (["smooth", out], ["slam", made / "b.npz", "--out", out]):
            proc = trunkslam(args, tmp_path)
            error_line(proc, out, "in use", f"pid {os.getpid()}")
        assert snapshot(out) == old
    assert not leftovers(out)  # the lock file goes with the lock
    proc = trunkslam(["smooth", out], tmp_path)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
def test_a_killed_holders_lock_is_released(made, tmp_path):
    out = shutil.copytree(made / "prev", tmp_path / "out")
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom experiments.io.outputs import lock_folder\n"
            f"with lock_folder({str(out)!r}, '--out'):\n"
            "    print('locked', flush=True)\n    time.sleep(600)\n",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert holder.stdout.readline().strip() == "locked"
    proc = trunkslam(["smooth", out], tmp_path)
    error_line(proc, "in use", f"pid {holder.pid}")
    holder.kill()
    holder.wait()
    proc = trunkslam(["smooth", out], tmp_path)  # the kernel dropped the dead holder's lock
    assert proc.returncode == 0, proc.stderr
    assert not leftovers(out)


PAIRS = r"""
import json, os, random, sys, time, traceback
from pathlib import Path

os.environ.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
spec = json.loads(sys.argv[1])
from experiments.cli import app
import experiments.pipeline.slam, experiments.pipeline.smooth, experiments.paper.reproduce
import slam.smoother  # every import before the forks: each command then costs its work only

folder, logs = Path(spec["folder"]), Path(spec["logs"])

def fork(args, log):
    pid = os.fork()
    if pid == 0:
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        code = 70
        try:
            app([str(a) for a in args], prog_name="trunkslam")
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        except BaseException:
            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    return pid

def wait(pid):
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])

def state():
    # what the folder holds: which command's set, and whether its files agree
    if not folder.exists():
        return {"mixed": False, "what": "absent", "why": []}
    files = {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}
    m = json.loads((folder / "manifest.json").read_text()) if "manifest.json" in files else {}
    listed = set(m.get("outputs", [])) | {"manifest.json"}
    why = [] if files == listed else [f"unlisted or missing: {sorted(files ^ listed)}"]
    what = m.get("command", "no manifest")
    if "summary.json" in files:
        n = json.loads((folder / "summary.json").read_text())["n_scans"]
        what += f" of {n} scans"
        smoothed = {"smoother.json", "trajectory_smoothed.csv"} & files
        if smoothed == {"smoother.json"}:
            why.append("smoother.json without its trajectory_smoothed.csv")
        elif smoothed:
            rows = len((folder / "trajectory_smoothed.csv").read_text().splitlines()) - 1
            s = json.loads((folder / "smoother.json").read_text()) if len(smoothed) == 2 else {}
            if not s.get("n_scans") == rows == n:
                got = f"smoother of {s.get('n_scans')} scans ({rows} rows)"
                why.append(f"{got} beside a run of {n}")
    return {"mixed": bool(why), "what": what, "why": why}

import shutil

def warm():
    # one slam, smooth and reproduce here, before the forks: each fork inherits their kernels
    # compiled instead of loading them from numba's cache again (about 0.5 s of CPU a command)
    scratch = folder.parent / "warm"
    for args in (["slam", spec["b"], "--out", scratch / "run"], ["smooth", scratch / "run"],
                 ["reproduce", "noise-calibration", "--quick", "--workers", "1",
                  "--out", scratch / "r"]):
        try:
            app([str(a) for a in args], prog_name="trunkslam")
        except SystemExit as e:
            assert not e.code, (args, e.code)
    shutil.rmtree(scratch)

warm()
import threading
# a fork copies only the forking thread: a thread left running by the warm-up (a progress
# heartbeat) could hold a lock the children then wait on for ever
assert threading.active_count() == 1, threading.enumerate()
rng = random.Random(spec["seed"])
results = []
for i, kind in enumerate(spec["pairs"]):
    shutil.rmtree(folder, ignore_errors=True)
    if kind == "smooth":  # a run of a.npz; smooth it while slam writes b.npz's run over it
        shutil.copytree(spec["run_a"], folder)
        other = ["smooth", folder]
        delay = rng.uniform(0.0, spec["smooth_window"])
    else:  # an empty place; reproduce and slam into it at once
        other = ["reproduce", "noise-calibration", "--quick", "--workers", "1", "--out", folder]
        delay = rng.uniform(0.0, spec["reproduce_window"])
    first = [other, ["slam", spec["b"], "--out", folder]]
    if rng.random() < 0.5:
        first.reverse()
    p1 = fork(first[0], logs / f"{i}.1")
    time.sleep(delay)  # the random timing under test, not a synchronisation
    p2 = fork(first[1], logs / f"{i}.2")
    codes = [wait(p1), wait(p2)]
    texts = [(logs / f"{i}.{k}").read_text() for k in (1, 2)]
    leftover = sorted(p.name for p in folder.parent.glob(f".{folder.name}.*"))
    results.append({
        "pair": kind, "order": [a[0] for a in first], "delay": delay, "codes": codes,
        "refused": ["in use" in t for t in texts],
        "other_set": ["is an output of `trunkslam" in t for t in texts],
        "tracebacks": ["Traceback" in t for t in texts],
        "leftovers": leftover, **state(),
    })
print(json.dumps(results))
"""


@pytest.mark.slow
def test_concurrent_commands_on_one_folder_never_mix_a_result_set(made, tmp_path):
    """100 pairs started a random 0-0.3 s apart (0-0.5 s with reproduce) on one folder: 96 of
    `smooth` on a run of a.npz against `slam b.npz` replacing it, 4 of `reproduce` against
    `slam` into an empty
    place. Each command either runs or is refused (exit 1, "in use"; or, for reproduce and slam,
    because the other's finished set is there, which neither replaces); the folder is always one
    command's complete set (every file in its manifest; a smoother's files of the run beside
    them). Each pair's processes are forks of one warmed-up process running the CLI's entry
    (`app`), so that 200 commands take seconds, not minutes of interpreter start-up; it has run
    each command once, so the forks also inherit the kernels compiled."""
    logs = tmp_path / "logs"
    logs.mkdir()
    spec = {
        "folder": str(tmp_path / "out"),
        "logs": str(logs),
        "run_a": str(made / "prev"),
        "b": str(made / "b.npz"),
        "seed": 29,
        "smooth_window": 0.3,
        "reproduce_window": 0.5,
        "pairs": ["smooth"] * 48 + ["reproduce"] * 2 + ["smooth"] * 48 + ["reproduce"] * 2,
    }
    proc = subprocess.run(
        [sys.executable, "-c", PAIRS, json.dumps(spec)],
        capture_output=True,
        text=True,
        timeout=900,
        preexec_fn=default_signals,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = json.loads(proc.stdout.splitlines()[-1])
    assert len(results) == 100
    mixed = [r for r in results if r["mixed"]]
    assert mixed == [], mixed[:3]
    for r in results:
        assert not any(r["tracebacks"]) and not r["leftovers"], r
        for code, refused, other in zip(r["codes"], r["refused"], r["other_set"]):
            # run, refused while the other runs, or refused after it: the folder is then the
            # other command's complete set, which this one must not replace
            assert code == 0 or (code == 1 and (refused or other)), r
    overlapped = sum(any(r["refused"]) for r in results)
    assert overlapped >= 10, overlapped  # the race was run, not dodged


# ---- killed runs leave no process ----------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("command", ["reproduce", "sweep"])
def test_kill_9_of_the_main_process_leaves_no_worker(command, tmp_path):
    env, marker = marked_env()
    out = tmp_path / "out"
    if command == "reproduce":
        args = ["reproduce", "table1", "--quick", "--workers", "2", "--out", out]
    else:
        spec = tmp_path / "s.toml"
        spec.write_text(
            'study = "association"\ntrials = 40\nseed = 1\n[base]\n"sim.n_scans" = 40\n'
            "[grid]\ngate_prob = [0.9, 0.99]\n"
        )
        args = ["sweep", spec, "--workers", "2", "--out", out]
    proc = start(args, tmp_path, env)
    try:
        workers = wait_for(
            lambda: [c for c in marked_processes(marker).values() if "spawn_main" in c][1:],
            120,
            "two worker processes",
        )
        assert proc.poll() is None, "the run ended before the workers were seen"
        started = marked_processes(marker)
        assert len(started) >= 3, started  # the main process, two workers (a resource tracker)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        t0 = time.monotonic()
        while marked_processes(marker) and time.monotonic() - t0 < 5.0:
            time.sleep(0.05)
        left = marked_processes(marker)
    finally:
        for pid in marked_processes(marker):  # never leave them to the next test
            os.kill(pid, signal.SIGKILL)
        proc.kill()
        proc.communicate()
    assert left == {}, (workers, left)


# ---- SIGTERM and SIGHUP --------------------------------------------------------------------


def _interrupted(point: str, sig: str, args: list, cwd: Path, marker_env=None):
    env = marker_env or dict(os.environ, PYTHONUNBUFFERED="1")
    env = dict(env, TRUNKSLAM_INTERRUPT_AT=point, TRUNKSLAM_INTERRUPT_SIGNAL=sig)
    return trunkslam(args, cwd, env=env)


def _aborted(proc, sig: str) -> None:
    """The clean-up path of Ctrl-C, then exit 128 + the signal's number with one error line
    naming the signal: not death by the signal."""
    error_line(proc, f"stopped by {sig}", code=128 + getattr(signal, sig))


@pytest.mark.slow
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_leave_the_old_outputs_and_nothing_temporary(made, tmp_path, sig):
    out = shutil.copytree(made / "prev", tmp_path / "out")
    old = snapshot(out)
    rrd = tmp_path / "run.rrd"
    rrd.write_bytes(b"an older recording")
    args = ["slam", made / "b.npz", "--features", "bailey", "--out", out, "--rerun", rrd]
    for point in ("recording-scan", "file-written"):
        proc = _interrupted(point, sig, args, tmp_path)
        _aborted(proc, sig)
        assert snapshot(out) == old, point
        assert not leftovers(out), (point, leftovers(out))
        assert not list(tmp_path.glob(".run.rrd.*")), point
    features = tmp_path / "f.json"
    features.write_text("{}")
    rrd.write_bytes(b"an older recording")
    args = ["extract", made / "a.npz", "--out", features, "--rerun", rrd]
    _aborted(_interrupted("recording-scan", sig, args, tmp_path), sig)
    assert features.read_text() == "{}" and rrd.read_bytes() == b"an older recording"
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
def test_sigterm_to_reproduce_with_workers_cleans_up_and_stops_them(tmp_path):
    """At the first result file (fault injection), and from outside once the temporary folder
    holds a file (as `timeout` or `docker stop` send it): exit 1, no `.out.partial-*`, and
    none of its processes left."""
    out = tmp_path / "out"
    args = ["reproduce", "table1", "--quick", "--workers", "2", "--out", out]
    env, marker = marked_env()
    proc = _interrupted("file-written", "SIGTERM", args, tmp_path, env)
    _aborted(proc, "SIGTERM")
    assert not out.exists() and not leftovers(out)
    wait_for(lambda: not marked_processes(marker), 5, "the workers to end")

    env, marker = marked_env()
    p = start(args, tmp_path, env)
    staged = wait_for(
        lambda: any(f.is_file() for s in tmp_path.glob(".out.partial-*") for f in s.rglob("*")),
        120,
        "a result file in the temporary folder",
        step=0.005,
    )
    assert staged and p.poll() is None
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 128 + signal.SIGTERM and "Traceback" not in err, err
    assert not out.exists() and not leftovers(out)
    wait_for(lambda: not marked_processes(marker), 5, "the workers to end")


@pytest.mark.slow
def test_an_ignored_sighup_stays_ignored(made, tmp_path):
    """`nohup trunkslam ...`: the hang-up the caller chose to ignore does not stop the run."""
    out = tmp_path / "out"
    env = dict(
        os.environ, TRUNKSLAM_INTERRUPT_AT="file-written", TRUNKSLAM_INTERRUPT_SIGNAL="SIGHUP"
    )

    def nohup() -> None:
        default_signals()
        signal.signal(signal.SIGHUP, signal.SIG_IGN)

    proc = subprocess.run(
        [sys.executable, "-m", "experiments.cli", "slam", str(made / "a.npz"), "--out", str(out)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        preexec_fn=nohup,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert (out / MANIFEST).is_file() and not leftovers(out)

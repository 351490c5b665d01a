"""Running `trunkslam` as a real process for the reliability tests (tests/ is on pytest's
pythonpath): the command, a one-line error check, and the processes a run left behind, found by
a marker in their environment (inherited by every process a command starts)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import uuid
from pathlib import Path

TRUNKSLAM = [sys.executable, "-m", "experiments.cli"]
MARKER_ENV = "TRUNKSLAM_TEST_MARKER"


def default_signals() -> None:
    """In the child before exec: SIGINT, SIGTERM and SIGHUP back to their defaults. A test
    suite started in the background (`make test &`) inherits SIGINT ignored, and a handler the
    command installs only replaces a default one."""
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)


def marked_env(**extra: str) -> tuple[dict, str]:
    """The environment for a command whose processes can be found afterwards, and its marker."""
    marker = uuid.uuid4().hex
    return dict(os.environ, PYTHONUNBUFFERED="1", **{MARKER_ENV: marker}, **extra), marker


def trunkslam(
    args: list[str], cwd: Path, env: dict | None = None, timeout: float = 180, preexec=None
) -> subprocess.CompletedProcess:
    """`trunkslam ARGS` as a process; its exit code and output."""

    def setup() -> None:
        default_signals()
        if preexec is not None:
            preexec()

    return subprocess.run(
        TRUNKSLAM + [str(a) for a in args],
        cwd=cwd,
        env=env if env is not None else dict(os.environ, PYTHONUNBUFFERED="1"),
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=setup,
    )


def start(args: list[str], cwd: Path, env: dict) -> subprocess.Popen:
    return subprocess.Popen(
        TRUNKSLAM + [str(a) for a in args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_signals,
    )


def error_line(proc: subprocess.CompletedProcess, *words: str, code: int = 1) -> str:
    """Exit `code` with one `error: ...` line naming every word, no traceback; the line."""
    err = proc.stderr
    assert proc.returncode == code, (proc.returncode, proc.stdout, err)
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1, err
    for w in words:
        assert str(w) in lines[0], (w, lines[0])
    return lines[0]


def marked_processes(marker: str) -> dict[int, str]:
    """{pid: command line} of the live processes (zombies left out) whose environment holds the
    marker."""
    found = {}
    needle = f"{MARKER_ENV}={marker}".encode()
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if needle not in (d / "environ").read_bytes().split(b"\0"):
                continue
            state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:  # gone meanwhile, or not ours to read
            continue
        if state not in ("Z", "X"):
            found[int(d.name)] = cmd
    return found

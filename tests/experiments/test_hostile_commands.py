"""Hostile commands (issue 43; tests/hostile_commands.py): `convert rosbag` on damaged bags,
links planted at locks and outputs, option extremes and the [closure] section end in a clear
error or a correct result, with every user and input file as it was.

First the issue's own findings, each one case of the audit (fast); then the lock file's own
checks; then the whole audit per kind, whose counts are the ones in docs/outputs.md (slow)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from hostile_commands import (
    KINDS,
    closure_cases,
    command_verdict,
    links_cases,
    option_cases,
    rosbag_cases,
)
from hostile_commands import audit as command_audit

from experiments.errors import DataError
from experiments.io.outputs import lock_folder

DOCS = Path(__file__).resolve().parents[2] / "docs" / "outputs.md"

# the cases the issue reports, by label (each a traceback, a hang or a file changed before)
FINDINGS = {
    "rosbag": [
        "an .mcap of its magic bytes",
        "random bytes named .bag",
        "metadata.yaml claims zstd (file)",
        "metadata.yaml claims zstd (message)",
        "a FIFO named .bag",
        "--laser-pose 1e300,0,0",
        "--laser-pose 0,0,1e9",
        "--out the bag folder's metadata.yaml (bag as its .db3)",
        "a negative scan stamp",
        "odometry only after the last scan",
        "a fix at latitude 95 deg",
    ],
    "links": [
        "slam: symlink at --out lock -> the user file",
        "slam: symlink at --out lock -> the input",
        "smooth: symlink at RUN_DIR lock -> the user file",
        "export-reference: symlink at --out lock -> the input",
        "slam: hard link at --out lock -> the user file",
        "sweep: FIFO at --out lock -> the user file",
        "smooth: symlink at smoother.json -> the user file",
    ],
    "options": [
        "reproduce --workers 10**30",
        "bench slam --trees 10**9",
        "bench smoother --chunks 2.5",
        "reproduce --dask bogus://x",
        "sweep [executor] dask = bogus://x",
        "slam --config /dev/zero",
        "slam --config /dev/urandom",
        "a sweep file at /dev/zero",
        "a sweep grid key of 5,000 dotted parts",
        "an input path that is not UTF-8 (slam)",
        "an --out path that is not UTF-8 (slam)",
        "a scene name with a NUL byte (simulate)",
        "--threads 10**30",
    ],
}
_LISTS = {"rosbag": rosbag_cases, "links": links_cases, "options": option_cases}


# the cases over about 1 s (pyproject.toml's `slow` marker): a sweep of its own
SLOW_FINDINGS = {"a sweep grid key of 5,000 dotted parts"}


def _finding_cases():
    for kind, labels in FINDINGS.items():
        by_label = {c.label: c for c in _LISTS[kind]()}
        for label in labels:
            marks = pytest.mark.slow if label in SLOW_FINDINGS else ()
            yield pytest.param(by_label[label], id=f"{kind}: {label}", marks=marks)


@pytest.mark.parametrize("case", list(_finding_cases()))
def test_the_issues_findings_are_clear_errors(case, tmp_path):
    """Each refused (exit 1 or 2) with an `error:` naming what is wrong, no traceback, no
    hang, and the user's file, the input and a planted link as they were."""
    verdict, detail = command_verdict(case, tmp_path)
    assert verdict == "clear", detail


@pytest.mark.parametrize("how", ["symlink", "hard link", "FIFO", "folder"])
def test_a_lock_file_that_is_not_a_plain_file_is_refused_naming_it(how, tmp_path):
    user = tmp_path / "thesis.tex"
    user.write_text("weeks of work\n")
    lock = tmp_path / ".out.lock"
    if how == "symlink":
        lock.symlink_to(user)
    elif how == "hard link":
        os.link(user, lock)
    elif how == "FIFO":
        os.mkfifo(lock)
    else:
        lock.mkdir()
    with pytest.raises(DataError) as e, lock_folder(tmp_path / "out"):
        pass
    assert f"its lock file {lock}" in str(e.value) and "refusing to write through it" in str(
        e.value
    )
    assert user.read_text() == "weeks of work\n"
    mode = os.lstat(lock).st_mode  # the planted entry is left where it was
    assert {"symlink": stat.S_ISLNK, "hard link": stat.S_ISREG, "FIFO": stat.S_ISFIFO,
            "folder": stat.S_ISDIR}[how](mode)  # fmt: skip


def test_a_stale_lock_file_is_taken_over_and_removed(tmp_path):
    """A regular lock file left by a killed process is still a lock (the checks above refuse
    links, not leftovers)."""
    lock = tmp_path / ".out.lock"
    lock.write_text("pid 1: trunkslam slam (killed)\n")
    with lock_folder(tmp_path / "out"):
        assert lock.read_text().startswith(f"pid {os.getpid()}:")
    assert not lock.exists()


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_every_hostile_command_is_a_clear_error_or_a_result(kind):
    """...and the counts in docs/outputs.md are this run's."""
    c = command_audit([kind], show=5)[kind]
    assert c["cases"] >= 30, c
    assert c["clear"] + c["ran"] == c["cases"], c
    row = [kind, c["cases"], c["clear"], c["ran"], c["unclear"], c["accepted"], c["traceback"]]
    assert f"| {' | '.join(map(str, row))} |" in DOCS.read_text(), row


def test_the_closure_kind_covers_every_closure_setting():
    from slam import SlamConfig

    fields = set(SlamConfig().to_dict()["closure"])
    covered = {c.label.split(" = ")[0].removeprefix("closure.") for c in closure_cases()}
    assert fields <= covered, fields - covered


@pytest.mark.parametrize(("fmt", "key"), [("sequence", "det_method"), ("run_log", "features"),
                                          ("run_log", "association")])  # fmt: skip
def test_a_method_name_that_is_a_number_is_refused(fmt, key, tmp_path):
    """A number where a method's name belongs (written as text by a tool that turned it into a
    string) was read as the name of a method."""
    import numpy as np
    from hostile import base_run_log, base_sequences, read, write_npz

    arrays = base_sequences()["full"] if fmt == "sequence" else base_run_log()
    path = write_npz(tmp_path / "hostile.npz", {**arrays, key: np.array("3.0")})
    with pytest.raises(DataError) as e:
        read(fmt, path)
    assert str(e.value) == f"{path}: {key}: '3.0' is a number, not the name of a method"

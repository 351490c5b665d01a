"""The audit's case list of hostile files (issue 29; tests/hostile.py): every case of every
format read by its reader gives the project's error naming the file and the key, never a
traceback, a silent acceptance or (sweep files) a late validation. Then the realistic runs the
audit found crashing at their end, and the limits on unbounded work."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hostile import FORMATS, audit
from typer.testing import CliRunner

from experiments.cli import app

runner = CliRunner()


LABELS = {
    "sequence": "sequence file",
    "run_log": "run log",
    "features": "features JSON",
    "config": "configuration",
    "sweep": "sweep file",
    "scene": "scene file",
}
DOCS = Path(__file__).resolve().parents[2] / "docs" / "outputs.md"


@pytest.mark.slow
@pytest.mark.parametrize("fmt", FORMATS)
def test_every_hostile_file_is_a_clear_error(fmt):
    """...and the counts in docs/outputs.md are this run's."""
    c = audit([fmt], show=5)[fmt]
    assert c["cases"] >= 200, c  # the list is the audit's, not a token few
    assert c["clear"] == c["cases"], c
    row = [LABELS[fmt], c["cases"], c["clear"], c["unclear"], c["accepted"], c["traceback"]]
    assert f"| {' | '.join(map(str, row))} |" in DOCS.read_text(), row


def _invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_a_one_scan_drive_has_no_gps_and_runs(tmp_path):
    res = _invoke("simulate-drive", "--scans", "1", "--out", tmp_path / "d1.npz")
    assert res.exit_code == 0, res.output
    with np.load(tmp_path / "d1.npz") as z:
        assert "gps_t" not in z.files and z["scan_t"].shape == (1,)
    res = _invoke("slam", tmp_path / "d1.npz", "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["n_scans"] == 1 and "gps" not in s


def test_two_scans_and_gps_only_after_the_last_scan_are_runs_not_crashes(tmp_path):
    """A 2-scan drive, and the same drive with its GPS moved after the last scan: the run and
    its smoothing finish; with no fix in the run, the summary says the GPS figures were not
    computed (JSON null), instead of NaN that JSON cannot hold."""
    res = _invoke("simulate-drive", "--scans", "2", "--out", tmp_path / "d2.npz")
    assert res.exit_code == 0, res.output
    res = _invoke("slam", tmp_path / "d2.npz", "--out", tmp_path / "o2", "--smooth")
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "o2" / "summary.json").read_text())["n_scans"] == 2
    res = _invoke("simulate-drive", "--scans", "40", "--seed", "3", "--out", tmp_path / "d.npz")
    assert res.exit_code == 0, res.output
    z = dict(np.load(tmp_path / "d.npz"))
    z["gps_t"] = z["gps_t"] + z["scan_t"][-1] + 1.0
    np.savez(tmp_path / "late.npz", **z)
    res = _invoke("slam", tmp_path / "late.npz", "--out", tmp_path / "late", "--smooth")
    assert res.exit_code == 0, res.output
    assert "not scored against GPS" in res.output
    text = (tmp_path / "late" / "summary.json").read_text()
    assert "NaN" not in text
    summary = json.loads(text)
    gps = summary["gps"]
    assert gps["matched"] == 0 and gps["all_rmse"] is None and gps["vouched_rmse"] is None, gps
    assert "no GPS fix within the run" in summary["not_computed"]["gps.all_rmse"]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["simulate-drive", "--scans", "10000000"], "1..100000"),
        (["bench", "raycast", "--repeats", "1000000000000"], "less than or equal to 100000"),
        (["bench", "association", "--repeats", "1000000000000"], "less than or equal to 100000"),
        (["bench", "extract", "--repeats", "1000"], "less than or equal to 100"),
    ],
)
def test_absurd_sizes_are_refused_naming_the_limit(args, words, tmp_path):
    res = _invoke(*args, *(["--out", tmp_path / "x.npz"] if args[0] == "simulate-drive" else []))
    assert res.exit_code in (1, 2) and words in res.output, res.output
    assert "Traceback" not in res.output


def _sequence_with_beams(path: Path, n_scans: int, n_beams: int) -> Path:
    from experiments.io.sequence_file import save_sequence
    from slam import Sequence

    t = np.arange(n_scans) * 0.2
    seq = Sequence(
        scan_t=t,
        scan_ranges=np.full((n_scans, n_beams), 5.0),
        scan_angle_min=-np.pi / 2,
        scan_angle_increment=np.pi / n_beams,
        laser_pose=np.zeros(3),
        odo_t=t,
        odo_speed=np.zeros(n_scans),
        odo_steer=np.zeros(n_scans),
    )
    return save_sequence(seq, path)


def test_a_million_beam_scan_is_refused_naming_the_limit(tmp_path):
    z = dict(np.load(_sequence_with_beams(tmp_path / "ok.npz", 2, 100)))
    z["scan_ranges"] = np.full((2, 1_000_000), 5.0)
    z["scan_angle_increment"] = np.array(np.pi / 1_000_000)
    z["scan_n_beams"] = np.array(1_000_000)
    np.savez(tmp_path / "wide.npz", **z)
    res = _invoke("slam", tmp_path / "wide.npz", "--out", tmp_path / "o")
    assert res.exit_code == 1 and "1000000 beams" in res.output and "MAX_BEAMS" in res.output
    assert str(tmp_path / "wide.npz") in res.output and "Traceback" not in res.output


MEMORY = """
import resource, sys
from experiments.io.sequence_file import load_sequence
from experiments.errors import DataError
vm = [int(x.split()[1]) * 1024 for x in open("/proc/self/status") if x.startswith("VmSize:")][0]
resource.setrlimit(resource.RLIMIT_AS, (vm + 150 * 2**20, resource.RLIM_INFINITY))
try:
    load_sequence(sys.argv[1])
except DataError as exc:
    print(exc)
    sys.exit(1)
"""


@pytest.mark.slow
def test_a_sequence_too_big_for_the_memory_limit_is_refused_before_reading(tmp_path):
    """Under an address-space limit 150 MB above what the process uses, a file with 104 MB of
    scans (which the run needs about three times over) is refused naming the memory it needs
    and the limit, instead of a MemoryError half-way through."""
    import subprocess
    import sys

    path = _sequence_with_beams(tmp_path / "big.npz", 1300, 10_000)
    proc = subprocess.run(
        [sys.executable, "-c", MEMORY, str(path)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 1, proc.stderr
    assert "of memory" in proc.stdout and "scan_ranges" in proc.stdout, proc.stdout
    assert str(path) in proc.stdout and "MemoryError" not in proc.stderr

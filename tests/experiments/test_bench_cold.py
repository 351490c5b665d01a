"""`trunkslam bench cold`: what it clears to make a checkout cold, and what it refuses."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from experiments.bench.cold import clear_caches, format_cold, project_root
from experiments.cli import app
from experiments.errors import DataError


def test_clear_caches_removes_numba_and_pytest_caches_but_not_the_venv(tmp_path):
    (tmp_path / "features" / "__pycache__").mkdir(parents=True)
    for name in ("extract.kernel-12.py311.nbi", "extract.kernel-12.py311.1.nbc", "x.pyc"):
        (tmp_path / "features" / "__pycache__" / name).write_bytes(b"x")
    venv_cache = tmp_path / ".venv" / "lib" / "numba" / "__pycache__"
    venv_cache.mkdir(parents=True)
    (venv_cache / "np.f-1.py311.nbi").write_bytes(b"x")
    (tmp_path / ".pytest_cache" / "d" / "numba-gw0").mkdir(parents=True)
    assert clear_caches(tmp_path) == 3
    assert sorted(p.name for p in (tmp_path / "features" / "__pycache__").iterdir()) == ["x.pyc"]
    assert (venv_cache / "np.f-1.py311.nbi").is_file()
    assert not (tmp_path / ".pytest_cache").exists()


def test_the_table_names_each_run_and_the_load(tmp_path):
    rows = [
        {"command": "make install", "run": "-", "wall_s": 61.2, "cpu_s": 50.1, "load_1min": 0.4},
        {"command": "make check", "run": "cold", "wall_s": 58.7, "cpu_s": 99.6, "load_1min": 1.2},
        {"command": "make check", "run": "warm", "wall_s": 31.4, "cpu_s": 52.0, "load_1min": 1.9},
    ]
    text = format_cold(rows)
    assert "| make check | cold | 59 | 100 | 1.2 |" in text
    assert "| make check | warm | 31 | 52 | 1.9 |" in text
    assert "cores" in text.splitlines()[0]


def test_project_root_is_this_checkout_and_a_plain_folder_is_refused(tmp_path):
    here = Path(__file__).resolve()
    assert here.is_relative_to(project_root(here.parent))
    with pytest.raises(DataError, match="not in a git checkout"):
        project_root(tmp_path)


def test_an_unknown_command_is_refused_before_any_clone(tmp_path):
    res = CliRunner().invoke(app, ["bench", "cold", "--commands", "check,tests", "--repo", "."])
    assert res.exit_code != 0
    assert "unknown command(s) ['tests']" in res.output

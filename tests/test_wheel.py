"""A wheel that works anywhere (issue 28): `pip install` of the built wheel gives a `trunkslam`
with its presets and scenes, away from the checkout.

What this proves: the wheel built from the project's own files (pyproject.toml, README.md and
the packages it names, copied without any build/ or egg-info left over) carries the presets and
scenes as package data, and the `trunkslam` it installs into a new venv, run from a folder
outside the checkout, lists the same presets as the checkout, reads them (`--dump-config` prints
the checkout's configuration), lists the bundled scenes in `simulate --help`, and simulates a
tree-park drive and runs SLAM on it with output files identical to the byte to the checkout's.
The venv imports our packages only from the wheel (checked: `experiments.__file__` is in the
venv and the checkout is not on `sys.path`).

The third-party dependencies are installed afresh into that venv from the wheel's own metadata
(the `dependencies` of pyproject.toml), by pip from its local cache or the package index, so a
dependency missing from pyproject.toml fails the test. They are constrained to the versions
of this environment (`pip freeze`), so that the byte comparison tests the wheel and not a newer
release of a dependency.

Building from a copy matters: setuptools also packs the files listed in a leftover
`*.egg-info/SOURCES.txt`, such as the editable install's in the checkout, so a wheel built in
place can carry data that pyproject.toml no longer declares.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
import venv
import zipfile
from pathlib import Path

import numpy as np
import pytest

from experiments.bundled import preset_names, scene_names
from experiments.io.config_file import config_toml, load_slam_config

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
PIP = [sys.executable, "-m", "pip"]


def _run(args: list, cwd: Path, env: dict) -> str:
    res = subprocess.run(
        [str(a) for a in args], cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )
    assert res.returncode == 0, f"{args}: exit {res.returncode}\n{res.stdout}\n{res.stderr}"
    return res.stdout


def _env(bin_dir: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return env


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel `pip wheel` builds from a clean copy of what the build reads."""
    root = tmp_path_factory.mktemp("wheel")
    src = root / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(REPO / name, src / name)
    find = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    for pattern in find["packages"]["find"]["include"]:
        pkg = pattern.rstrip("*")
        shutil.copytree(REPO / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    dist = root / "dist"
    _run([*PIP, "wheel", "--no-deps", "-q", "-w", dist, src], root, dict(os.environ))
    (whl,) = dist.glob("trunkslam-*.whl")
    return whl


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """The bin/ folder of a new venv holding the wheel and the dependencies it declares."""
    root = tmp_path_factory.mktemp("venv")
    env_dir = root / "venv"
    venv.create(env_dir, with_pip=False)
    bin_dir = env_dir / "bin"
    pins = root / "constraints.txt"  # this environment's versions, not the newest releases
    pins.write_text(_run([*PIP, "freeze", "--exclude-editable"], root, dict(os.environ)))
    # --no-compile: pip would byte-compile every module of every dependency (scipy, numba,
    # gtsam, ...; about 20 s of CPU), while the commands below import a few of them, which
    # Python compiles as they load; what is installed, and so what the test checks, is the same
    install = ["--python", bin_dir / "python", "install", "-q", "--no-compile", "-c", pins, wheel]
    _run([*PIP, *install], root, dict(os.environ))
    return bin_dir


def test_the_wheel_carries_the_presets_and_scenes(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {f"experiments/presets/{p}.toml" for p in preset_names()} <= names
    assert {f"experiments/scenes/{s}.json" for s in scene_names()} <= names
    assert not any(n.startswith(("datasets/", "tests/")) for n in names)
    (licence,) = [n for n in names if n.endswith(".dist-info/licenses/LICENSE")]
    assert zipfile.ZipFile(wheel).read(licence) == (REPO / "LICENSE").read_bytes()


def test_the_installed_command_works_outside_the_checkout(installed, tmp_path):
    env = _env(installed)
    code = "import experiments, sys; print(experiments.__file__, *sys.path, sep=chr(10))"
    where, *path = _run([installed / "python", "-c", code], tmp_path, env).splitlines()
    assert Path(where).is_relative_to(installed.parent) and str(REPO) not in path, (where, path)
    code = "import gtsam, numba, rerun, scipy; print(gtsam.__file__, numba.__file__, sep=chr(10))"
    deps = _run([installed / "python", "-c", code], tmp_path, env).splitlines()
    assert all(Path(d).is_relative_to(installed.parent) for d in deps), deps

    trunkslam = installed / "trunkslam"
    listed = [ln.split()[0] for ln in _run([trunkslam, "presets"], tmp_path, env).splitlines()]
    assert listed == preset_names() and {"cycab", "victoria_park_ute"} <= set(listed)
    assert "--config" in _run(
        [trunkslam, "slam", "--config", "victoria_park_ute", "--help"], tmp_path, env
    )
    dumped = _run(
        [trunkslam, "slam", "--config", "victoria_park_ute", "--dump-config"], tmp_path, env
    )
    want = config_toml(load_slam_config("victoria_park_ute"))
    assert tomllib.loads(dumped.split("\n", 1)[1]) == tomllib.loads(want)
    helped = _run([trunkslam, "simulate", "--help"], tmp_path, env)
    assert all(s in helped for s in scene_names())

    # the same drive and run by the wheel and by the checkout (the editable install)
    checkout = Path(sys.executable).parent / "trunkslam"
    for exe, d in [(trunkslam, tmp_path / "wheel"), (checkout, tmp_path / "checkout")]:
        d.mkdir()
        _run(
            [exe, "simulate-drive", "tree_park", "--scans", "20", "--out", "run.npz"],
            d,
            _env(exe.parent),
        )
        _run([exe, "slam", "run.npz", "--out", "o"], d, _env(exe.parent))
    a, b = np.load(tmp_path / "wheel" / "run.npz"), np.load(tmp_path / "checkout" / "run.npz")
    assert a.files == b.files
    for k in a.files:  # the simulated ranges hold NaN (no return)
        assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k
    for name in ("trajectory.tum", "map.csv", "config.toml"):
        got = (tmp_path / "wheel" / "o" / name).read_bytes()
        assert got == (tmp_path / "checkout" / "o" / name).read_bytes(), name
    assert len((tmp_path / "wheel" / "o" / "trajectory.tum").read_text().splitlines()) == 20

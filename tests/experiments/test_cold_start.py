"""A first run's first line (issue 44): on a cold numba cache the compile notice comes before
the imports, from numba's cache folders found without numba; none when the kernels are cached."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rich.console import Console

import experiments.render.cold_start as cold_start
import experiments.render.compiling as compiling
from experiments.render.progress import Progress

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def clock(monkeypatch):
    """A fresh compile clock: the notice not yet said in this process."""
    fresh = compiling._Clock()
    fresh.registered = True  # no listener on numba's events here
    monkeypatch.setattr(compiling, "_CLOCK", fresh)
    return fresh


def _fill(files=cold_start.KERNEL_FILES) -> None:
    """An index where numba keeps each file's kernels (as a cached run leaves one)."""
    for name in files:
        folder = cold_start.cache_folder(cold_start._ROOT / name)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{Path(name).stem}._kernel-10.py311.nbi").write_bytes(b"")


def test_an_empty_cache_is_cold_and_a_filled_one_warm(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nb"))
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    assert cold_start.kernels_cached() is False
    _fill(cold_start.KERNEL_FILES[:-1])
    assert cold_start.kernels_cached() is False  # one package's kernels still missing
    assert cold_start.kernels_cached(cold_start.KERNEL_FILES[:-1]) is True
    _fill()
    assert cold_start.kernels_cached() is True
    folders = {cold_start.cache_folder(cold_start._ROOT / f) for f in cold_start.KERNEL_FILES}
    assert len(folders) == 3 and all(f.parent == tmp_path / "nb" for f in folders)


def test_nothing_compiles_without_the_jit(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("NUMBA_DISABLE_JIT", "1")
    assert cold_start.kernels_cached() is True


def test_the_notice_is_said_once_cold_and_never_warm(tmp_path, monkeypatch, clock):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    said: list[str] = []
    _fill()
    assert not cold_start.say_if_cold(say=said.append) and said == []  # warm: nothing
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty"))
    assert cold_start.say_if_cold(say=said.append)
    assert not cold_start.say_if_cold(say=said.append)  # once per process
    clock.say = said.append
    clock.on_start()  # the first real compile then says nothing more
    clock.on_end()
    assert said == [compiling.COMPILING_NOTICE]


def test_the_heartbeat_counts_from_the_early_notice(tmp_path, monkeypatch, clock):
    """The imports after the notice are silence too: the first progress display's heartbeat
    comes `heartbeat_s` after the notice, not after the display started (later displays count
    from their own start)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    assert cold_start.say_if_cold(say=lambda line: None)
    time.sleep(1.5)  # the imports
    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    console = Console(file=io.StringIO(), force_terminal=False)
    t0 = time.perf_counter()
    with Progress(console=console, heartbeat_s=2.0):
        while "still" not in err.getvalue() and time.perf_counter() - t0 < 8:
            time.sleep(0.01)
    first_beat = time.perf_counter() - t0
    assert "still working" in err.getvalue()
    # 2 s after the notice, 1.5 s of it before the display: about 0.5 s in, where counting from
    # the display's start would say it at 2 s (a wide margin either side for a loaded machine)
    assert first_beat < 1.4, first_beat
    assert compiling.take_early_notice() is None  # taken by that display


def _numba_folders(env: dict) -> dict[str, list[str]]:
    """Per kernel file, numba's own cache folder and index name of one of its kernels."""
    code = f"""
import importlib, json
out = {{}}
for name in {cold_start.KERNEL_FILES!r}:
    module = importlib.import_module(name[:-3].replace("/", "."))
    kernel = next(v for v in vars(module).values() if getattr(v, "_cache", None) is not None
                  and getattr(v._cache, "_cache_path", None)
                  and v.py_func.__module__ == module.__name__)
    out[name] = [kernel._cache._cache_path, kernel._cache._cache_file._index_name]
print(json.dumps(out))
"""
    res = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@pytest.mark.slow
@pytest.mark.parametrize("given", [True, False], ids=["NUMBA_CACHE_DIR", "beside-the-source"])
def test_the_cache_folders_are_numbas_own(tmp_path, monkeypatch, given):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    if given:
        env["NUMBA_CACHE_DIR"] = str(tmp_path)
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    else:
        monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    for name, (folder, index) in _numba_folders(env).items():
        assert Path(folder) == cold_start.cache_folder(cold_start._ROOT / name), name
        assert index.startswith(Path(name).stem + ".") and index.endswith(".nbi"), index


def _slam(args: list[str], cache: Path) -> subprocess.CompletedProcess:
    env = os.environ | {"NUMBA_CACHE_DIR": str(cache), "TERM": "dumb"}
    cmd = [sys.executable, "-m", "experiments.cli", "slam", *args]
    return subprocess.run(cmd, env=env, cwd=cache.parent, capture_output=True, text=True)


@pytest.mark.slow
def test_a_cold_slam_says_the_notice_first(tmp_path, monkeypatch):
    """`trunkslam slam` on a cold cache: the notice is its first line (here an unreadable file
    then ends it, so nothing compiles); on a cached one, no notice."""
    bad = tmp_path / "bad.npz"
    bad.write_text("not a sequence")
    res = _slam([str(bad)], tmp_path / "cold")
    lines = res.stderr.splitlines()
    assert res.returncode == 1 and lines[0] == compiling.COMPILING_NOTICE, res.stderr
    assert lines[1].startswith("error:") and "bad.npz" in lines[1]
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "warm"))
    _fill()
    res = _slam([str(bad)], tmp_path / "warm")
    assert res.returncode == 1 and res.stderr.splitlines()[0].startswith("error:"), res.stderr


def test_first_line_times_the_first_line_then_stops_the_command(tmp_path):
    from experiments.bench.startup import first_line

    talk = "import sys, time; time.sleep(0.3); print('x', file=sys.stderr, flush=True); "
    t0 = time.perf_counter()
    wall, cpu = first_line([sys.executable, "-c", talk + "time.sleep(60)"], tmp_path, {})
    assert 0.3 <= wall < time.perf_counter() - t0 < 30  # stopped, not waited for
    assert 0 < cpu < wall
    with pytest.raises(RuntimeError, match="no line"):
        first_line([sys.executable, "-c", "pass"], tmp_path, {})

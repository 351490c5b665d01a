"""tests/conftest.py's warm numba cache folder: warmed once per state of the kernels' sources,
marked when its warm-up succeeded, and not warmed again while marked (a warm `make check` ran
the warm-up every time only to load, about 4 s of one core before the workers started)."""

from __future__ import annotations

import subprocess
from pathlib import Path
from types import SimpleNamespace

import conftest

ROOT = Path(__file__).resolve().parents[1]


def test_a_warmed_folder_is_not_warmed_again_and_a_failed_warm_up_leaves_no_mark(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv(conftest.WARM_CACHE_ENV, "")  # restored (unset) after the test
    monkeypatch.delenv(conftest.WARM_CACHE_ENV)
    config = SimpleNamespace(rootpath=ROOT)
    runs = []
    codes = iter([1, 0])

    def run(args, **kw):
        runs.append(kw["env"]["NUMBA_CACHE_DIR"])
        return subprocess.CompletedProcess(args, next(codes))

    monkeypatch.setattr(conftest.subprocess, "run", run)
    conftest._warm_shared_cache(config)  # fails: no mark, no warm folder for the workers
    folder = Path(runs[0])
    assert folder.parent == tmp_path and not (folder / conftest.WARMED_MARKER).exists()
    assert conftest.WARM_CACHE_ENV not in conftest.os.environ
    conftest._warm_shared_cache(config)  # succeeds: marked
    assert runs == [str(folder)] * 2 and (folder / conftest.WARMED_MARKER).is_file()
    assert conftest.os.environ[conftest.WARM_CACHE_ENV] == str(folder)
    conftest._warm_shared_cache(config)  # marked: not run again
    assert len(runs) == 2


def test_the_folder_follows_the_kernels_sources_and_numbas_version(monkeypatch):
    digest = conftest._kernel_sources_digest(ROOT)
    assert digest == conftest._kernel_sources_digest(ROOT)
    monkeypatch.setattr(conftest, "_numba_version", lambda: "0.0.0")
    assert conftest._kernel_sources_digest(ROOT) != digest

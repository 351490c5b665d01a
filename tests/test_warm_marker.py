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


def test_two_runs_at_once_warm_the_folder_once(tmp_path, monkeypatch):
    """The second run waits for the first's warm-up (a lock beside the folder), then finds the
    folder marked and does not warm it again."""
    import threading

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv(conftest.WARM_CACHE_ENV, "")
    config = SimpleNamespace(rootpath=ROOT)
    started, release, runs = threading.Event(), threading.Event(), []

    def run(args, **kw):
        runs.append(kw["env"]["NUMBA_CACHE_DIR"])
        started.set()
        assert release.wait(30)
        return subprocess.CompletedProcess(args, 0)

    monkeypatch.setattr(conftest.subprocess, "run", run)
    first = threading.Thread(target=conftest._warm_shared_cache, args=(config,))
    first.start()
    assert started.wait(30)
    second = threading.Thread(target=conftest._warm_shared_cache, args=(config,))
    second.start()
    second.join(0.5)
    assert second.is_alive()  # waiting on the lock while the first warms
    release.set()
    first.join(30)
    second.join(30)
    assert not first.is_alive() and not second.is_alive()
    assert len(runs) == 1


def test_absorbing_unmarks_the_folder_while_it_changes_and_copies_whole_files(tmp_path):
    warm, worker = tmp_path / "warm", tmp_path / "gw0"
    for folder in (warm, worker):
        (folder / "features").mkdir(parents=True)
    (warm / conftest.WARMED_MARKER).touch()
    (warm / "features" / "k-1.py311.nbi").write_bytes(b"old index")
    (warm / "features" / "k-1.py311.1.nbc").write_bytes(b"one")
    (worker / "features" / "k-1.py311.nbi").write_bytes(b"new index")
    for i in (1, 2):
        (worker / "features" / f"k-1.py311.{i}.nbc").write_bytes(b"sig %d" % i)
    seen = []
    real = conftest._copy_whole

    def copy(source, target):
        seen.append((target.name, (warm / conftest.WARMED_MARKER).exists()))
        real(source, target)

    conftest._copy_whole = copy
    try:
        conftest._absorb_kernels(warm, [worker])
    finally:
        conftest._copy_whole = real
    assert seen == [
        ("k-1.py311.1.nbc", False),
        ("k-1.py311.2.nbc", False),
        ("k-1.py311.nbi", False),  # the index last
    ]
    assert (warm / conftest.WARMED_MARKER).is_file()
    assert (warm / "features" / "k-1.py311.nbi").read_bytes() == b"new index"
    assert sorted(p.name for p in (warm / "features").iterdir()) == [
        "k-1.py311.1.nbc",
        "k-1.py311.2.nbc",
        "k-1.py311.nbi",
    ]  # no part file left
    conftest._absorb_kernels(warm, [worker])  # nothing more to take: the mark stays
    assert (warm / conftest.WARMED_MARKER).is_file()


def test_the_digest_follows_the_warm_up_but_not_other_experiment_files(tmp_path):
    for name, text in (
        ("features/k.py", "@njit\ndef k(): pass\n"),
        ("experiments/bench/warm.py", "WARM = 1\n"),
        ("experiments/cli/x.py", "X = 1\n"),
    ):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    digest = conftest._kernel_sources_digest(tmp_path)
    (tmp_path / "experiments/cli/x.py").write_text("X = 2\n")
    assert conftest._kernel_sources_digest(tmp_path) == digest
    (tmp_path / "experiments/bench/warm.py").write_text("WARM = 2\n")
    assert conftest._kernel_sources_digest(tmp_path) != digest

"""Shared fixtures and settings.

Real data: `vp_dir` is the Victoria Park folder under TRUNKSLAM_DATA (read by
experiments/io/paths.py). When the data are absent the tests that need them are skipped, unless
TRUNKSLAM_REQUIRE_DATA=1 (CI), in which case they fail with a message saying what is missing.

Hypothesis profiles: `ci` draws the same examples on every run (`derandomize=True`, no example
database), so that CI's verdict does not depend on the seed; `make test` and `make check` pass
`--hypothesis-profile=ci`. `dev`, loaded when no profile is named (a plain `pytest`), draws new
examples on every run and replays the failures it saved in .hypothesis/; the property tests must
pass under it too (`pytest -m hypothesis --hypothesis-seed=N`).

Parallel runs (pytest-xdist, `-n auto`): every test writes under its own tmp_path, and each
worker process gets its own numba cache folder (NUMBA_CACHE_DIR, inherited by the processes it
starts), because numba's cache is not safe for two processes compiling one function at once
(a cold cache, or a source file just edited): a process writes the function's index before its
data file, so another can read an index entry whose file is not written yet or is an older one
of the same name, and two processes compiling different signatures take the same file number,
so one signature's entry can end up naming the other's code. So that a fresh clone does not
compile every kernel once per worker, the controlling process first compiles them once, alone,
into a shared folder (`python -m experiments.bench.warm`: every extractor, a short simulated
drive with each associator and loop closure; a cold folder in two processes, each writing a
folder of its own, then merged), and each worker starts from a copy of it: its own
folder, warm. A signature the warm-up did not compile is compiled by the worker that needs it,
as before.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import settings

REQUIRE_DATA_ENV = "TRUNKSLAM_REQUIRE_DATA"

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("dev", derandomize=False, print_blob=True)
settings.load_profile("dev")  # `--hypothesis-profile=ci` loads `ci` after this file is read


WARM_CACHE_ENV = "TRUNKSLAM_WARM_NUMBA_CACHE"  # the controller's warm cache, for the workers
WARMED_MARKER = "warmed"  # in the warm cache folder once a warm-up there has succeeded


def pytest_configure(config: pytest.Config) -> None:
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if not worker:
        if getattr(config.option, "numprocesses", None):  # before the workers start
            _warm_shared_cache(config)
        return  # one process: numba's default cache beside the sources, BLAS as it starts
    _share_the_cores(int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    _own_numba_cache(config, worker)


def _cache_folder(config: pytest.Config, name: str) -> Path:
    parent = os.environ.get("NUMBA_CACHE_DIR")
    if parent:
        return Path(parent) / f"xdist-{name}"
    if getattr(config, "cache", None) is not None:
        return config.cache.mkdir(f"numba-{name}")
    return config.rootpath / ".pytest_cache" / "d" / f"numba-{name}"


def _kernel_sources_digest(root: Path) -> str:
    """A digest of every source file of the packages that hold numba kernels (and of the other
    files that hold one, and of the warm-up that decides what is compiled), and of numba's
    version. numba drops a cached kernel only when its own
    file changes, not when a kernel it calls from another file does (`slam.scan_candidates`
    calls `slam.se2.observe_kernel`): a warm cache keyed by every source never serves a kernel
    compiled against an older callee. A folder of this digest that a warm-up has completed
    (`WARMED_MARKER`) holds every kernel the warm-up compiles, so it is not run again there."""
    h = hashlib.sha256(_numba_version().encode() + b"\0")
    for package in ("features", "association", "slam"):
        for path in sorted((root / package).rglob("*.py")):
            h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes() + b"\0")
    warm_up = root / "experiments" / "bench" / "warm.py"  # what is compiled: a new kernel
    for path in sorted((root / "experiments").rglob("*.py")):  # its kernels (eval/vouched.py)
        text = path.read_bytes()
        if path == warm_up or b"@njit" in text:
            h.update(str(path.relative_to(root)).encode() + b"\0" + text + b"\0")
    return h.hexdigest()[:16]


def _numba_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("numba")
    except PackageNotFoundError:
        return "?"


def _warm_shared_cache(config: pytest.Config) -> None:
    """Compile every kernel once, in one process, into the folder the workers copy (see the
    module docstring), a folder per state of the kernels' sources (`_kernel_sources_digest`;
    the others are removed). A warm-up that fails leaves the workers to compile as they go.
    Two test runs started together (two checkouts' `make check`, or CI beside a developer's
    run) take turns on one folder: the first warms it, the second waits and finds it marked."""
    folder = _cache_folder(config, f"warm-{_kernel_sources_digest(config.rootpath)}")
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f"{folder.name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        for old in folder.parent.glob(folder.name.split("-warm-")[0] + "-warm-*"):
            if old != folder and old.is_dir():
                shutil.rmtree(old, ignore_errors=True)
        folder.mkdir(parents=True, exist_ok=True)
        if (folder / WARMED_MARKER).is_file() or _run_warm_up(config, folder):
            os.environ[WARM_CACHE_ENV] = str(folder)


def _run_warm_up(config: pytest.Config, folder: Path) -> bool:
    """`python -m experiments.bench.warm` into `folder`; marks it warmed when it succeeds."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(folder), "OMP_NUM_THREADS": "1"}
    try:  # its two lines show at once: a cold warm-up takes a minute
        done = subprocess.run(
            [sys.executable, "-m", "experiments.bench.warm"],
            env=env,
            cwd=config.rootpath,
            timeout=1800,
        )
    except (OSError, subprocess.SubprocessError) as exc:
        sys.stderr.write(f"numba warm-up failed ({exc}); each worker compiles its own kernels\n")
        return False
    if done.returncode != 0:
        sys.stderr.write("numba warm-up failed (above); each worker compiles its own kernels\n")
        return False
    (folder / WARMED_MARKER).touch()
    return True


# the BLAS (and OpenMP) threads a worker may use, and the limit each one holds
_BLAS_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_blas_limit = None


def _share_the_cores(workers: int) -> None:
    """Give each of `workers` processes its share of the cores for BLAS (at least 1 thread),
    in this process and in the ones it starts. OpenBLAS starts one thread per core in every
    process, and its threads spin while they wait: with more busy threads than cores the
    Victoria Park runs slow down fourfold (the consistency-scale test: 39 s with 2 BLAS threads,
    10 s with 1, on 2 cores with other work running)."""
    global _blas_limit
    threads = max(1, (os.cpu_count() or 1) // max(workers, 1))
    for var in _BLAS_THREADS:
        os.environ.setdefault(var, str(threads))
    import numpy  # noqa: F401  (loads the BLAS that threadpoolctl then limits)
    from threadpoolctl import threadpool_limits

    _blas_limit = threadpool_limits(limits=int(os.environ["OPENBLAS_NUM_THREADS"]))


def _own_numba_cache(config: pytest.Config, worker: str) -> None:
    """This worker's numba cache folder (see the module docstring), a copy of the controller's
    warm cache when it made one."""
    folder = _cache_folder(config, worker)
    warm = os.environ.get(WARM_CACHE_ENV)
    if warm and Path(warm).is_dir():
        shutil.rmtree(folder, ignore_errors=True)  # a function's index and data files as one
        shutil.copytree(warm, folder)
    folder.mkdir(parents=True, exist_ok=True)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # read at import: make numba see the new folder
        from numba.core import config as numba_config

        numba_config.reload_config()


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """The controller, once its workers have ended a run that was not interrupted: the kernels
    and signatures the tests compiled and the warm-up did not (loop closure's matcher, a
    360-degree scan's extractor, ...) join the warm cache, so that the next run's workers start
    with them instead of compiling them again (about 50 s of CPU a run of the fast tier)."""
    warm = os.environ.get(WARM_CACHE_ENV)
    if os.environ.get("PYTEST_XDIST_WORKER") or not warm or exitstatus not in (0, 1):
        return
    pattern = _cache_folder(session.config, "gw0").name.replace("gw0", "gw*")
    with open(Path(warm).parent / f"{Path(warm).name}.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # not while another run warms or absorbs into it
        _absorb_kernels(Path(warm), sorted(Path(warm).parent.glob(pattern)))


def _absorb_kernels(warm: Path, workers: list[Path]) -> None:
    """Copy into `warm` each function whose cache a worker holds with more signatures: its data
    files and then its index, all from that one worker (a function's files as one; no process
    writes either folder now)."""
    best: dict[tuple[str, str], tuple[int, Path]] = {}
    for folder in workers:
        for index in folder.glob("*/*.nbi"):
            sub, stem = index.parent.name, index.name.removesuffix(".nbi")
            n = len(list(index.parent.glob(f"{stem}.*.nbc")))
            if (
                n > len(list((warm / sub).glob(f"{stem}.*.nbc")))
                and n > best.get((sub, stem), (0, folder))[0]
            ):
                best[(sub, stem)] = (n, folder)
    if not best:
        return
    # unmarked while it changes: a run killed here leaves a folder the next run warms again
    # (its warm-up loads what is whole and compiles what is not) instead of one it trusts
    (warm / WARMED_MARKER).unlink(missing_ok=True)
    for (sub, stem), (_, folder) in best.items():
        (warm / sub).mkdir(parents=True, exist_ok=True)
        for data in sorted((folder / sub).glob(f"{stem}.*.nbc")):
            _copy_whole(data, warm / sub / data.name)
        _copy_whole(folder / sub / f"{stem}.nbi", warm / sub / f"{stem}.nbi")
    (warm / WARMED_MARKER).touch()


def _copy_whole(source: Path, target: Path) -> None:
    """`source` to `target` by a temporary file renamed over it: `target` is the old file or
    the whole new one, never a part."""
    part = target.with_name(f".{target.name}.part")
    shutil.copy2(source, part)
    os.replace(part, target)


def _missing_data(message: str) -> None:
    if os.environ.get(REQUIRE_DATA_ENV, "").strip() == "1":
        pytest.fail(
            f"{message} ({REQUIRE_DATA_ENV}=1, so missing data is a failure)", pytrace=False
        )
    pytest.skip(f"{message} (set {REQUIRE_DATA_ENV}=1 to make this a failure)")


@pytest.fixture(scope="session")
def vp_dir() -> Path:
    """The Victoria Park folder with every file the readers use; skip or fail if absent."""
    from experiments.errors import DataError
    from experiments.io.paths import victoria_park_dir
    from experiments.io.victoria_park import VP_FILES

    try:
        d = victoria_park_dir()
    except DataError as exc:
        _missing_data(f"Victoria Park data not available: {exc}")
    missing = [f for f in VP_FILES.values() if not (d / f).is_file()]
    if missing:
        _missing_data(f"Victoria Park data incomplete in {d}: missing {missing}")
    return d


def made_once(tmp_path_factory, name: str, make) -> Path:
    """A folder `make(folder)` filled once for the whole test run: under pytest-xdist each
    worker has its own session, so a session fixture was made once per worker (25 s of CPU for
    the quick Victoria Park set, twice when its two modules went to two workers). The first
    worker to ask makes it, holding a lock, in the folder all workers' temporary folders share;
    the others wait for it, then read it (read-only, as the session fixtures say). A make that
    fails leaves the next one to try again."""
    base = tmp_path_factory.getbasetemp()
    # popen workers' folders (popen-gw0, ...) sit in this run's own basetemp; any other layout
    # (no xdist, other gateways) keeps to its own folder, never one shared across runs
    shared = os.environ.get("PYTEST_XDIST_WORKER") and base.name.startswith("popen-")
    root = base.parent if shared else base
    folder, made = root / f"once-{name}", root / f"once-{name}.made"
    with open(root / f"once-{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not made.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            make(folder)
            made.touch()
    return folder


@pytest.fixture(scope="session")
def noise_calibration_set(tmp_path_factory) -> Path:
    """A complete result set of `trunkslam reproduce noise-calibration --quick --seed 0` (the
    quickest experiment), made once a test run (`made_once`): the earlier results that the
    interruption, full-disk and failed-experiment tests copy and then try to replace. Read-only:
    copy it.
    One worker (`--workers 1`): its trials in this process, as on any executor (the results do
    not depend on it, tests/experiments/test_exec.py), without starting a pool of processes
    that each import the project and load the kernels (about 15 s of CPU)."""
    from typer.testing import CliRunner

    from experiments.cli import app

    def make(folder: Path) -> None:
        out = folder / "results"
        args = ["reproduce", "noise-calibration", "--quick", "--seed", "0", "--workers", "1"]
        res = CliRunner().invoke(app, [*args, "--out", str(out)])
        assert res.exit_code == 0, res.output

    out = made_once(tmp_path_factory, "noise_calibration", make) / "results"
    assert (out / "noise_calibration.csv").is_file() and (out / "manifest.json").is_file()
    return out


@pytest.fixture(scope="session")
def quick_victoria_park_set(tmp_path_factory, vp_dir) -> Path:
    """`trunkslam reproduce victoria-park --quick` on shorter data (the first 150 scans of the
    full run and 100 raw scans, instead of 1500 and 400, so that it takes seconds), made once a
    test run (`made_once`): its tables (test_result_tables.py) and the configuration files it
    writes beside them, which do not depend on the number of scans (test_run_is_its_config.py).
    Read-only."""
    from experiments.paper.reproduce import run_experiments
    from experiments.paper.victoria_park import real_run as vp

    def make(out: Path) -> None:
        full, raw, ref = vp._data(True)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(vp, "_data", lambda quick: (vp.head(full, 150), vp.head(raw, 100), ref))
            run_experiments(["victoria-park"], out, quick=True, seed=0)

    return made_once(tmp_path_factory, "vp_tables", make)

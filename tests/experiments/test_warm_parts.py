"""`python -m experiments.bench.warm`: the parts' numba caches merged into one folder, a
kernel's files from one part only, and a merged folder serving numba without a compile."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from experiments.bench.warm import main, merge_kernels


def _kernel(folder: Path, stem: str, n_data: int, tag: bytes) -> None:
    sub = folder / "work" / "features"
    sub.mkdir(parents=True, exist_ok=True)
    (sub / f"{stem}.nbi").write_bytes(tag + b" index")
    for i in range(1, n_data + 1):
        (sub / f"{stem}.{i}.nbc").write_bytes(tag + b" data %d" % i)


def test_merge_takes_each_kernel_whole_from_the_first_part_that_holds_it(tmp_path):
    a, b, target = tmp_path / "a", tmp_path / "b", tmp_path / "target"
    _kernel(a, "extract.f-10.py311", 2, b"a")
    _kernel(a, "extract.g-20.py311", 1, b"a")
    _kernel(b, "extract.g-20.py311", 2, b"b")  # in both parts: a's files alone
    _kernel(b, "extract.h-30.py311", 1, b"b")
    _kernel(target, "extract.k-40.py311", 1, b"t")  # already there: left as it is
    _kernel(b, "extract.k-40.py311", 3, b"b")
    assert merge_kernels(target, [a, b]) == 3
    sub = target / "work" / "features"
    files = {p.name: p.read_bytes() for p in sub.iterdir()}
    assert files == {
        "extract.f-10.py311.nbi": b"a index",
        "extract.f-10.py311.1.nbc": b"a data 1",
        "extract.f-10.py311.2.nbc": b"a data 2",
        "extract.g-20.py311.nbi": b"a index",
        "extract.g-20.py311.1.nbc": b"a data 1",
        "extract.h-30.py311.nbi": b"b index",
        "extract.h-30.py311.1.nbc": b"b data 1",
        "extract.k-40.py311.nbi": b"t index",
        "extract.k-40.py311.1.nbc": b"t data 1",
    }


def test_jobs_below_one_is_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--jobs", "0"])
    assert exc.value.code == 2
    assert "--jobs: must be >= 1, got 0" in capsys.readouterr().err


_KERNEL = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2.0 * x
"""

_CALL = """
import sys
sys.path.insert(0, sys.argv[1])
from kern import twice
assert twice(1.5) == 3.0
print(sum(twice.stats.cache_hits.values()), sum(twice.stats.cache_misses.values()))
"""


@pytest.mark.slow
def test_a_kernel_merged_from_a_part_is_loaded_not_compiled(tmp_path):
    """numba keys a kernel's cache by its source's path, not by the cache folder: the files a
    part wrote into its own folder serve a process of the merged one (a hit, no compile)."""
    src = tmp_path / "src"
    src.mkdir()
    (src / "kern.py").write_text(textwrap.dedent(_KERNEL))

    def call(cache: Path) -> list[int]:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
        out = subprocess.run(
            [sys.executable, "-c", _CALL, str(src)],
            env=env,
            capture_output=True,
            text=True,
            check=True,
            timeout=300,
        )
        return [int(v) for v in out.stdout.split()]

    assert call(tmp_path / "part") == [0, 1]  # compiled, into the part's folder
    assert merge_kernels(tmp_path / "merged", [tmp_path / "part"]) == 1
    assert call(tmp_path / "merged") == [1, 0]  # loaded from the merged folder


def test_the_last_pass_is_skipped_only_when_the_merge_loses_no_signature(tmp_path):
    """A kernel two parts hold with one index (the same signatures) loses nothing in the merge;
    with two different indexes, the merge keeps one part's and the last pass must run."""
    from experiments.bench.warm import merge_loses_nothing

    a, b = tmp_path / "a", tmp_path / "b"
    _kernel(a, "extract.f-10.py311", 1, b"a")
    _kernel(b, "extract.h-30.py311", 1, b"b")
    assert merge_loses_nothing([a, b])
    _kernel(b, "extract.f-10.py311", 1, b"a")  # the same index in both parts
    assert merge_loses_nothing([a, b])
    _kernel(b, "extract.f-10.py311", 2, b"b")  # another signature in b's
    assert not merge_loses_nothing([a, b])
    assert merge_loses_nothing([a])

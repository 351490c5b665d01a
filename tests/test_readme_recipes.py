"""Every snippet and recipe of the README and the getting-started page runs, in the order
written, in a fresh folder (issue 44).

Each document gets its own empty folder that sees the checkout's `datasets/` and `examples/`
(links: the recipes name them as a clone's root has them) and the venv's commands first on
PATH. Its ```sh blocks run line by line through bash (a line's `&&` and `>` as written), its
```python blocks through this Python, all in the order of the page, so a recipe that uses a
file a later one makes fails. The lines in `SKIPPED` are not run, each for the reason given
(the viewer, the Makefile, the runs of minutes to hours that other tests and `make reproduce`
cover); a skipped line that no longer appears in the page fails the test, so the list cannot
hide a new recipe.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
DOCUMENTS = ("README.md", "docs/getting-started.md")

SKIPPED = {
    "make install": "the Makefile's venv: this test runs in one",
    "source .venv/bin/activate": "the venv's bin/ is first on PATH here",
    "make reproduce": "every experiment at full size (hours); CI runs it",
    "make test": "the whole suite, this test among it",
    ".venv/bin/rerun seq.rrd": "opens the viewer (tests/experiments/test_recordings.py reads it)",
    "rerun run.rrd": "opens the viewer",
    "trunkslam reproduce": "every experiment at full size (hours)",
    "trunkslam reproduce table3 table4 --out /tmp/r --seed 1 --workers 2": "minutes",
    "trunkslam reproduce table3 table4": "minutes (tests/experiments/test_reproduce.py)",
    "trunkslam reproduce --quick --out quick": "minutes (tests/experiments/test_reproduce.py)",
    "trunkslam reproduce loop-closure": "minutes (tests/experiments/test_loop_closure.py)",
    "trunkslam sweep datasets/sweeps/sweep_slam_noise.toml --out sweep_slam_noise": (
        "180 runs (tests/experiments/test_exec.py runs sweeps)"
    ),
    "trunkslam bench slam": "minutes (make bench)",
    "trunkslam report results": "needs a full reproduce run's results/, rewrites the docs",
}

_FENCE = re.compile(r"^```(\w+)\n(.*?)^```", re.MULTILINE | re.DOTALL)


def blocks(document: str) -> list[tuple[str, str]]:
    """[(language, code)] of the page's fenced blocks, in order."""
    return [(m[1], m[2]) for m in _FENCE.finditer((REPO / document).read_text())]


def commands(code: str) -> list[str]:
    """The shell lines of an sh block: comments and blank lines left out."""
    out = []
    for line in code.splitlines():
        line = line.split(" #", 1)[0].strip() if not line.lstrip().startswith("#") else ""
        if line:
            out.append(line)
    return out


def _run(args: list[str], cwd: Path, what: str) -> None:
    env = dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ['PATH']}", COLUMNS="100")
    res = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    assert res.returncode == 0, f"{what}\nexit {res.returncode}\n{res.stdout}\n{res.stderr}"


def test_no_skipped_line_is_stale():
    lines = {
        c for d in DOCUMENTS for lang, code in blocks(d) if lang == "sh" for c in commands(code)
    }
    assert set(SKIPPED) <= lines, sorted(set(SKIPPED) - lines)


@pytest.mark.parametrize("document", DOCUMENTS)
def test_the_recipes_run_in_order(document, tmp_path, vp_dir):  # noqa: ARG001 (needs the data)
    for name in ("datasets", "examples"):
        (tmp_path / name).symlink_to(REPO / name)
    ran = 0
    for lang, code in blocks(document):
        if lang == "sh":
            for line in commands(code):
                if line in SKIPPED:
                    continue
                _run(["bash", "-c", line], tmp_path, f"{document}: {line}")
                ran += 1
        elif lang == "python":
            _run([sys.executable, "-c", code], tmp_path, f"{document}:\n{code}")
            ran += 1
    assert ran >= 5, ran

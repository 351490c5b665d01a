"""The registry of experiments (`experiments.paper.registry`): what the command line reads from
the source is what the modules register, and the contributing page's example works."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import numpy as np
import pytest

from experiments.io.writers import read_tidy_csv
from experiments.paper import registry
from experiments.paper.runner import DEFAULT_EXPERIMENTS, EXPERIMENTS, RunContext

ROOT = Path(__file__).resolve().parents[2]


def test_what_the_source_declares_is_what_the_modules_register():
    for path in sorted((ROOT / "experiments" / "paper").rglob("*.py")):
        importlib.import_module(".".join(path.relative_to(ROOT).with_suffix("").parts))
    assert registry.REGISTERED == registry.declared() == EXPERIMENTS
    assert list(EXPERIMENTS) == [
        e.name for e in sorted(registry.REGISTERED.values(), key=lambda e: e.order)
    ]
    assert "table1" in DEFAULT_EXPERIMENTS and "victoria-park-rfs" not in DEFAULT_EXPERIMENTS
    assert EXPERIMENTS["table1"].target == EXPERIMENTS["table2"].target  # one run, two names
    for e in EXPERIMENTS.values():  # every experiment has its page
        assert (ROOT / "docs" / "experiments" / e.page).is_file(), e


def test_reproduce_help_lists_the_registered_lines():
    lines = registry.help_lines().split("\n\n")
    assert len(lines) == len(registry.groups()) == len(EXPERIMENTS) - 2  # table2, table4 share
    assert lines[1].startswith("- table1, table2: circle-centre")


def _example(tmp_path: Path) -> Path:
    """The example module of docs/contributing.md, written to a file."""
    page = (ROOT / "docs" / "contributing.md").read_text()
    code = re.search(r"```python\n(.*?)```", page, re.S).group(1)
    path = tmp_path / "spacing.py"
    path.write_text(code)
    return path


def test_the_contributing_example_declares_and_runs(tmp_path, monkeypatch):
    path = _example(tmp_path)
    [e] = registry.declarations(path, "spacing")
    assert (e.name, e.target, e.order, e.page, e.default) == (
        "tree-spacing",
        "spacing:run",
        130,
        "tree-spacing.md",
        False,
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "REGISTERED", {})
    module = importlib.import_module("spacing")
    assert registry.REGISTERED == {"tree-spacing": e}  # the decorator registered what was read
    out = tmp_path / "out"
    out.mkdir()
    module.run(RunContext(out_dir=out))
    rows = read_tidy_csv(out / "tree_spacing.csv")
    assert [r["scene"] for r in rows] == ["tree_park", "pillar_court"]
    assert all(np.isfinite(float(r["median_m"])) and float(r["median_m"]) > 0.1 for r in rows)


@pytest.mark.parametrize(
    ("decorator", "error"),
    [
        ('@experiment("Table_9", order=1, page="x.md", help="h")', "lower-case words"),
        ('@experiment(order=1, page="x.md", help="h")', "lower-case words"),
        ('@experiment("x", order=1, page="x.md", help="h")\n@functools.cache', "last decorator"),
        ('@experiment("x", order=ORDER, page="x.md", help="h")', "malformed"),
    ],
)
def test_a_declaration_the_source_reading_cannot_read_is_refused(tmp_path, decorator, error):
    path = tmp_path / "m.py"
    path.write_text(f"{decorator}\ndef run(ctx):\n    pass\n")
    with pytest.raises(ValueError, match=error):
        registry.declarations(path, "m")

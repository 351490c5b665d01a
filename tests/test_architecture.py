"""The import arrows of STYLE.md section 1, read from the source (AST).

- packages: `features` and `association` import nothing of ours, `slam` may import both,
  `experiments` anything, and nothing imports `experiments`;
- rooms of `experiments`: a room imports only rooms below it (`errors` at the bottom; `io`,
  `sim`, `eval` and `exec` never import `paper`, `bench`, `pipeline`, `render` or `cli`);
- third-party packages confined to one module (gtsam, rerun, matplotlib, dask);
- no private name (`_x`) or private module imported from another module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OURS = {"features", "association", "slam", "experiments"}
ALLOWED = {
    "features": {"features"},
    "association": {"association"},
    "slam": {"slam", "features", "association"},
    "experiments": OURS,
}
# room -> the rooms of experiments/ it may import (besides itself)
ROOMS = {
    "errors": set(),
    "io": {"errors"},
    "sim": {"errors"},
    "eval": {"errors"},
    "exec": {"errors"},
    "render": {"errors", "io"},
    "pipeline": {"errors", "io", "sim", "eval", "render", "exec"},
    "paper": {"errors", "io", "sim", "eval", "render", "exec"},
    "bench": {"errors", "io", "sim", "eval", "render", "exec", "paper"},
    "cli": {"errors", "io", "sim", "eval", "render", "exec", "paper", "bench", "pipeline"},
}
# third-party packages confined to one module
CONFINED = {
    "gtsam": "slam/smoother.py",
    "rerun": "experiments/render/viz.py",
    "matplotlib": "experiments/render/plots.py",
    "dask": "experiments/exec/cluster.py",
    "distributed": "experiments/exec/cluster.py",
}


def imported_modules(path: Path) -> set[str]:
    """Full dotted names of every module `path` imports (absolute imports)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
            out |= {f"{node.module}.{a.name}" for a in node.names}
    return out


def top_level(path: Path) -> set[str]:
    return {m.split(".")[0] for m in imported_modules(path)}


def room(rel: Path) -> str:
    """The room of experiments/<room>/... or experiments/<room>.py (the package's own __init__
    counts as cli: it may import anything)."""
    part = rel.parts[1]
    return "cli" if part == "__init__.py" else part.removesuffix(".py")


FILES = sorted(p for pkg in OURS for p in (ROOT / pkg).rglob("*.py"))
EXPERIMENTS = [p for p in FILES if p.relative_to(ROOT).parts[0] == "experiments"]


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_flow_one_way(path):
    pkg = path.relative_to(ROOT).parts[0]
    bad = (top_level(path) & OURS) - ALLOWED[pkg]
    assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"
    rel = str(path.relative_to(ROOT))
    for lib, home in CONFINED.items():
        if lib in top_level(path):
            assert rel == home, f"{rel} imports {lib}; only {home} may"


@pytest.mark.parametrize("path", EXPERIMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_rooms_import_only_rooms_below(path):
    rel = path.relative_to(ROOT)
    here = room(rel)
    assert here in ROOMS, f"{rel}: experiments/{here} is not a known room; add it to ROOMS"
    used = {m.split(".")[1] for m in imported_modules(path) if m.startswith("experiments.")}
    bad = used - ROOMS[here] - {here}
    assert not bad, f"{rel} (room {here}) imports rooms {sorted(bad)}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_private_names_cross_modules(path):
    own = ".".join(path.relative_to(ROOT).with_suffix("").parts)
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] not in OURS or node.module == own:
                continue
            private = [a.name for a in node.names if a.name.startswith("_")]
            modules = [p for p in node.module.split(".") if p.startswith("_")]
            assert not private and not modules, f"{own} imports {node.module}: {private}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in OURS:
                    assert not any(p.startswith("_") for p in a.name.split(".")), a.name


def test_the_checks_see_files():
    assert len(FILES) > 40 and len(EXPERIMENTS) > 20
    assert "features" in top_level(ROOT / "features" / "__init__.py")
    assert {room(p.relative_to(ROOT)) for p in EXPERIMENTS} == set(ROOMS)
    assert "experiments.io.writers" in imported_modules(ROOT / "experiments/render/plots.py")


def test_library_code_never_points_into_tests():
    """No path into tests/ is built in library code (golden files are written by
    tests/regenerate_golden.py); docstrings may name a test file."""
    for path in FILES:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                v = node.value
                assert v != "tests" and "tests/golden" not in v, f"{path}: {v[:60]!r}"


def test_datasets_is_not_a_python_package():
    assert not (ROOT / "datasets" / "__init__.py").exists()

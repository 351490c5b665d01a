"""The import arrows of STYLE.md section 1, read from the source (AST)."""

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
# third-party packages confined to one module
CONFINED = {
    "gtsam": "slam/smoother.py",
    "rerun": "experiments/viz.py",
    "matplotlib": "experiments/plots.py",
}


def imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module.split(".")[0])
    return out


FILES = sorted(p for pkg in OURS for p in (ROOT / pkg).rglob("*.py"))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_flow_one_way(path):
    pkg = path.relative_to(ROOT).parts[0]
    bad = (imports(path) & OURS) - ALLOWED[pkg]
    assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"
    rel = str(path.relative_to(ROOT))
    for lib, home in CONFINED.items():
        if lib in imports(path):
            assert rel == home, f"{rel} imports {lib}; only {home} may"


def test_the_check_sees_files():
    assert len(FILES) > 10
    assert "features" in imports(ROOT / "features" / "__init__.py")


def test_datasets_is_not_a_python_package():
    assert not (ROOT / "datasets" / "__init__.py").exists()

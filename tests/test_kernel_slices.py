"""No numba kernel assigns an array to a slice of another (`z[:, 1] = b`, `P[a:b, a:b] = C`):
numba compiles that assignment's shape-mismatch message (f-strings, str.join, int to str) once
per process and per rank, about 5 s of CPU in each process that compiles such a kernel, the
cold warm-up's two parts included (lab notebook, 2026-11-29). The kernels copy element by
element instead (`features.extract._copy_block`, `slam.scan_candidates._put_row`). This reads
the source: it sees a slice in the index, not an integer index of a higher-rank array
(`H5[a] = H[i]`), which the same helpers replace."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _kernels():
    for package in ("features", "association", "slam", "experiments"):
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text())
            for fn in ast.walk(tree):
                if isinstance(fn, ast.FunctionDef) and any(
                    "njit" in ast.unparse(d) for d in fn.decorator_list
                ):
                    yield path.relative_to(ROOT), fn


def _slice_assignments(fn: ast.FunctionDef):
    for node in ast.walk(fn):
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AugAssign):
            targets, value = [node.target], node.value
        else:
            continue
        for t in targets:
            sliced = isinstance(t, ast.Subscript) and any(
                isinstance(n, ast.Slice) for n in ast.walk(t.slice)
            )
            if sliced and not isinstance(value, ast.Constant):
                yield node.lineno, ast.unparse(node)


def test_the_kernels_are_found():
    names = {fn.name for _, fn in _kernels()}
    assert {"_extract_kernel", "scan_candidates", "observe_kernel", "sub_problem"} <= names


def test_no_kernel_assigns_an_array_to_a_slice():
    found = [
        f"{path}:{line} {fn.name}: {text}"
        for path, fn in _kernels()
        for line, text in _slice_assignments(fn)
    ]
    assert found == []

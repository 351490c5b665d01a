"""The import arrows of STYLE.md section 1, read from the source (AST).

- packages: `features` and `association` import nothing of ours, `slam` may import both,
  `experiments` anything, and nothing imports `experiments`;
- rooms of `experiments`: a room imports only rooms below it (`errors` and `bundled`, the
  package data's folders, at the bottom; `io`, `sim`, `eval` and `exec` never import `paper`,
  `bench`, `pipeline`, `render` or `cli`);
- third-party packages confined to one module (gtsam, rerun, dask, rosbags), matplotlib to the
  figure modules (`experiments/render/plots.py`, `experiments/paper/**/*figures.py`);
- no private name (`_x`) or private module imported from another module;
- no import circle among the modules of the packages (imports inside functions count too);
- STYLE.md section 4b's signs of a missing name: no function over 80 lines (numba kernels
  aside; in the packages, tests/, docs/*.py and examples/) and no call with more than five
  positional arguments in the packages (calls of numba kernels, of a logger and of builtins
  aside).
"""

from __future__ import annotations

import ast
import builtins
import re
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
    "bundled": set(),
    "io": {"errors", "bundled"},
    "sim": {"errors", "bundled"},
    "eval": {"errors"},
    "exec": {"errors"},
    "render": {"errors", "bundled", "io"},
    "pipeline": {"errors", "bundled", "io", "sim", "eval", "render", "exec"},
    "paper": {"errors", "bundled", "io", "sim", "eval", "render", "exec"},
    "bench": {"errors", "bundled", "io", "sim", "eval", "render", "exec", "paper"},
    "cli": {"errors", "bundled", "io", "sim", "eval", "render", "exec"}
    | {"paper", "bench", "pipeline"},
}
# matplotlib: the figure modules (each experiment's, beside it) and their shared helpers
FIGURE_MODULES = re.compile(r"experiments/(render/plots|paper/(\w+/)?(\w+_)?figures)\.py")
# third-party packages confined to one module
CONFINED = {
    "gtsam": "slam/smoother.py",
    "rerun": "experiments/render/viz.py",
    "dask": "experiments/exec/cluster.py",
    "distributed": "experiments/exec/cluster.py",
    "rosbags": "experiments/io/rosbag.py",
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
    tops = top_level(path)  # parsed once: six confined libraries are checked below
    bad = (tops & OURS) - ALLOWED[pkg]
    assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"
    rel = str(path.relative_to(ROOT))
    for lib, home in CONFINED.items():
        if lib in tops:
            assert rel == home, f"{rel} imports {lib}; only {home} may"
    if "matplotlib" in top_level(path):
        assert FIGURE_MODULES.fullmatch(rel), f"{rel} imports matplotlib; only figure modules may"


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
    tree = TREES[path]  # parsed once, at import (below)
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
    assert {p.relative_to(ROOT).parts[0] for p in READ_TOO} == {"tests", "docs", "examples"}
    assert "features" in top_level(ROOT / "features" / "__init__.py")
    assert {room(p.relative_to(ROOT)) for p in EXPERIMENTS} == set(ROOMS)
    assert "experiments.io.writers" in imported_modules(ROOT / "experiments/render/plots.py")


def test_library_code_never_points_into_tests():
    """No path into tests/ is built in library code (golden files are written by
    tests/regenerate_golden.py); docstrings may name a test file."""
    for path in FILES:
        for node in ast.walk(TREES[path]):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                v = node.value
                assert v != "tests" and "tests/golden" not in v, f"{path}: {v[:60]!r}"


def module_name(path: Path) -> str:
    """The dotted module of a file of the packages (a package's __init__ is the package)."""
    return ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")


def import_graph(files) -> dict[str, set[str]]:
    """Module -> the modules of `files` it imports (`from a.b import c` imports a.b.c when c
    is a module of `files`, a.b otherwise)."""
    names = {module_name(p) for p in files}
    graph = {}
    for path in files:
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name in names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                for a in node.names:
                    full = f"{node.module}.{a.name}"
                    deps |= {full} if full in names else {node.module} & names
        graph[module_name(path)] = deps - {module_name(path)}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of `graph`: its strongly connected components of more than one
    module (Tarjan's algorithm, iterative), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_no_import_circles():
    """No module of slam/, features/, association/ or experiments/ imports, through others, a
    module that imports it: each module can be read (and tested) after the ones it uses."""
    found = circles(import_graph(FILES))
    assert not found, f"import circles: {found}"


def test_the_circle_check_sees_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e2"}, "e2": set()}
    assert circles(graph) == [["a", "b", "c"]]
    assert circles({"x": {"y"}, "y": {"x"}, "z": set()}) == [["x", "y"]]
    assert "slam.config" in import_graph(FILES)["slam.checks"]


def test_datasets_is_not_a_python_package():
    assert not (ROOT / "datasets" / "__init__.py").exists()


# ---- STYLE.md section 4b: a function longer than a screen, a call with too many arguments -------

MAX_FUNCTION_LINES = 80
MAX_POSITIONAL = 5
KERNEL_DECORATORS = {"njit", "vectorize"}  # numba's: a kernel is one loop, not split for reading
LOGGERS = {"log", "logger", "logging"}  # log.info("%s ... %s", a, b, ...): a format's arguments
BUILTINS = set(dir(builtins))  # zip(a, b, c, ...), print, range, max, min, ...
# Calls allowed by where they are and what they call, with the reason.
ALLOWED_CALLS = {
    # the numba segmentation kernel or its plain-numpy twin (the test oracle), chosen by name
    # from a dict: the same arguments as the kernel
    ("features/segmentation.py", "kernels[kernel]")
}


def _trees() -> dict[Path, ast.Module]:
    return {p: ast.parse(p.read_text(), filename=str(p)) for p in FILES}


TREES = _trees()


def _name(node: ast.expr) -> str:
    """The last name of a decorator or a callee: njit for `njit`, `numba.njit(cache=True)`."""
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _is_kernel(fn: ast.FunctionDef) -> bool:
    return any(_name(d) in KERNEL_DECORATORS for d in fn.decorator_list)


def _functions(tree: ast.Module):
    return [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]


# every numba kernel of the packages, by name: a kernel's arguments are arrays and scalars
KERNELS = {fn.name for tree in TREES.values() for fn in _functions(tree) if _is_kernel(fn)}


def long_functions(tree: ast.Module) -> list[str]:
    """Every function (nested ones too) over MAX_FUNCTION_LINES lines from its def to its last
    line, numba kernels aside, as "name (line): n lines"."""
    return [
        f"{fn.name} (line {fn.lineno}): {fn.end_lineno - fn.lineno + 1} lines"
        for fn in _functions(tree)
        if fn.end_lineno - fn.lineno + 1 > MAX_FUNCTION_LINES and not _is_kernel(fn)
    ]


def _call_allowed(call: ast.Call, rel: str) -> bool:
    f = call.func
    if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id in LOGGERS:
        return True
    if isinstance(f, ast.Name) and f.id in BUILTINS:
        return True
    return _name(f) in KERNELS or (rel, ast.unparse(f)) in ALLOWED_CALLS


def long_calls(tree: ast.Module, rel: str) -> list[str]:
    """Every call with more than MAX_POSITIONAL positional arguments (a *starred one counts
    once), but for kernels, loggers and builtins, as "callee (line): n positional"."""
    return [
        f"{ast.unparse(n.func)} (line {n.lineno}): {len(n.args)} positional"
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and len(n.args) > MAX_POSITIONAL and not _call_allowed(n, rel)
    ]


# beyond the packages, the function-length check reads the tests, the docs' scripts and examples
READ_TOO = sorted(
    [
        *(ROOT / "tests").rglob("*.py"),
        *(ROOT / "docs").glob("*.py"),
        *(ROOT / "examples").rglob("*.py"),
    ]
)


@pytest.mark.parametrize("path", FILES + READ_TOO, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_function_over_80_lines(path):
    """A function longer than a screen is a concept without a name (STYLE.md section 4b)."""
    tree = TREES[path] if path in TREES else ast.parse(path.read_text(), filename=str(path))
    bad = long_functions(tree)
    assert not bad, f"{path.relative_to(ROOT)}: {bad}"


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_call_with_more_than_five_positional_arguments(path):
    """A call with more than five positional arguments is a record waiting to exist (STYLE.md
    section 4b): give the arguments keywords, or the record a type."""
    rel = str(path.relative_to(ROOT))
    bad = long_calls(TREES[path], rel)
    assert not bad, f"{rel}: {bad}"


def test_the_size_checks_see_what_they_check():
    """The checks find a long function and a long call in code written for it, and leave
    kernels, loggers, builtins and the allowed call alone."""
    src = (
        "from numba import njit\n"
        "@njit(cache=True)\n"
        "def kern(a, b, c, d, e, f):\n" + "    a = 1\n" * 90 + "    return a\n"
        "def long(x):\n" + "    x += 1\n" * 80 + "    return x\n"
        "def short(x):\n    return x\n"
        "def caller(a, b, c, d, e, f):\n"
        "    kern(a, b, c, d, e, f)\n"
        "    segment_kernel(a, b, c, d, e, f)\n"
        "    log.info('%s %s %s %s %s', a, b, c, d, e)\n"
        "    zip(a, b, c, d, e, f)\n"
        "    kernels[kernel](a, b, c, d, e, f)\n"
        "    record(a, b, c, d, e, f)\n"
        "    record(*(a, b, c, d, e, f))\n"
    )
    tree = ast.parse(src)
    assert long_functions(tree) == ["long (line 95): 82 lines"]
    # only the packages' own kernels are allowed (segment_kernel), not any njit function
    assert "segment_kernel" in KERNELS and "kern" not in KERNELS

    def callees(rel: str) -> list[str]:
        return [c.split(" (")[0] for c in long_calls(tree, rel)]

    # the call through the dict is allowed in segmentation.py only; *starred counts once
    assert callees("features/segmentation.py") == ["kern", "record"]
    assert callees("elsewhere.py") == ["kern", "kernels[kernel]", "record"]

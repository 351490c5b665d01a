"""The registry of experiments: each experiment registers itself where it is written.

An experiment is a function of a `RunContext` (`experiments.paper.runner`) in a module under
experiments/paper/, declared by the decorator right above it:

    @experiment("table3", "table4", order=40, page="slam.md",
                help="EKF-SLAM Monte Carlo on the simulated tree park (one run), ...")
    def run(ctx: RunContext) -> None: ...

Everything else is built from these declarations: `trunkslam reproduce`'s and `trunkslam bench
reproduce`'s choice of names and the list in `reproduce --help` (`experiments.cli`), the run
order and the default run (`experiments.paper.runner`), and the experiments' index in the
documentation (docs/experiments/index.md, by docs/hooks/results.py). Adding an experiment is a
module with its decorated function, plus its page under docs/experiments/.

The command line must list the names without importing the experiments (numpy, scipy and the
rest would make `--help` slow), so `declared()` reads the decorators from the modules' source
text; importing a module runs the same decorators, which register into `REGISTERED`, and
`experiments.paper.runner.get_experiment` checks that the two agree. This module imports
nothing but the standard library.
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "REGISTERED",
    "Experiment",
    "declarations",
    "declared",
    "experiment",
    "groups",
    "help_lines",
    "index_table",
]

PACKAGE = Path(__file__).resolve().parent  # experiments/paper
_DECORATOR = re.compile(r"^@experiment\(", re.MULTILINE)
_FUNCTION = re.compile(r"^(?:async )?def (\w+)", re.MULTILINE)


@dataclass(frozen=True)
class Experiment:
    """One registered name.

    name: the name `trunkslam reproduce NAME` takes.
    names: every name of its function (table1 and table2 are one run), this one among them.
    target: "module:function", the function called with a RunContext.
    help: what it does, in one line of `trunkslam reproduce --help`.
    page: its page under docs/experiments/ (e.g. "slam.md").
    order: its place in the run (ascending; the names of one function follow each other).
    default: whether `trunkslam reproduce` without names runs it.
    """

    name: str
    names: tuple[str, ...]
    target: str
    help: str
    page: str
    order: int
    default: bool = True


REGISTERED: dict[str, Experiment] = {}  # filled as experiment modules are imported


def experiment(
    *names: str, help: str, page: str, order: int, default: bool = True
) -> Callable[[Callable], Callable]:
    """Register the decorated function as the experiment(s) `names` (see the module doc).
    The arguments must be literals: `declared()` reads them without running the module."""

    def register(fn: Callable) -> Callable:
        target = f"{fn.__module__}:{fn.__name__}"
        for e in _entries(names, target, help=help, page=page, order=order, default=default):
            REGISTERED[e.name] = e
        return fn

    return register


def _entries(
    names: tuple[str, ...], target: str, *, help: str, page: str, order: int, default: bool = True
) -> list[Experiment]:
    if not names or any(not re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", n) for n in names):
        raise ValueError(f"experiment names must be lower-case words joined by '-': {names}")
    return [
        Experiment(n, tuple(names), target, help=help, page=page, order=order + k, default=default)
        for k, n in enumerate(names)
    ]


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent.parent).with_suffix("")
    return ".".join(rel.parts)


def declarations(path: Path, module: str) -> list[Experiment]:
    """The experiments the module `module` (source file `path`) declares: each
    `@experiment(...)` decorator at the start of a line, its arguments read as literals, and the
    function defined after it."""
    text = path.read_text(encoding="utf-8")
    found = []
    for m in _DECORATOR.finditer(text):
        fn = _FUNCTION.search(text, m.end())
        source = text[m.start() + 1 : fn.start()].strip()
        if "\n@" in source:  # another decorator between it and the function
            raise ValueError(f"{path}: @experiment must be the function's last decorator")
        call = ast.parse(source, mode="eval").body
        args = [ast.literal_eval(a) for a in call.args]
        kwargs = {k.arg: ast.literal_eval(k.value) for k in call.keywords}
        target = f"{module}:{fn.group(1)}"
        found += _entries(tuple(args), target, **kwargs)
    return found


@functools.cache
def declared() -> dict[str, Experiment]:
    """Every experiment declared under experiments/paper/, by name, in run order (read from
    the source, nothing imported)."""
    found: list[Experiment] = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name != "registry.py":
            found += declarations(path, _module_name(path))
    names = [e.name for e in found]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"experiments registered twice: {twice}")
    return {e.name: e for e in sorted(found, key=lambda e: (e.order, e.name))}


def groups() -> list[tuple[Experiment, ...]]:
    """The registered experiments grouped by function (table1 and table2 together), in order."""
    out: dict[str, list[Experiment]] = {}
    for e in declared().values():
        out.setdefault(e.target, []).append(e)
    return [tuple(g) for g in out.values()]


def help_lines() -> str:
    """The experiments as `trunkslam reproduce --help` lists them: "- names: help" paragraphs."""
    return "\n\n".join(f"- {', '.join(e.name for e in g)}: {g[0].help}" for g in groups())


def _title(page: Path) -> str:
    """A page's title: its first `# ` heading, else its file name."""
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return page.stem


def index_table(pages: Path) -> str:
    """The documentation's index of experiments (Markdown): page, what it runs, the names of
    `trunkslam reproduce`, one row per experiment function; `pages`: docs/experiments/."""
    rows = ["| page | experiment | `trunkslam reproduce` names |", "|---|---|---|"]
    for g in groups():
        e = g[0]
        names = " ".join(x.name for x in g)
        rows.append(f"| [{_title(pages / e.page)}]({e.page}) | {e.help} | `{names}` |")
    return "\n".join(rows)

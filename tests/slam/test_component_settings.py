"""Each component of a run is built from its own section's settings, never the whole
`SlamConfig` (issue 40): the configuration is resolved at the edge (`slam.loop.run_slam`,
`slam.components.components`, the run's checks and start) and a component receives scalars or
its one section. Read from the source (AST), so a class that takes or reads the whole
configuration fails here."""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

import pytest

from slam.config import SlamConfig

SLAM = Path(__file__).resolve().parents[2] / "slam"

# the edge: where the configuration is read and split into the components' settings
EDGE = {"config.py", "checks.py", "components.py", "start.py", "__init__.py"}
SECTIONS = {f.name for f in fields(SlamConfig)}


def _component_modules() -> list[Path]:
    return sorted(p for p in SLAM.glob("*.py") if p.name not in EDGE)


def _offences(tree: ast.AST) -> list[str]:
    """Every class in the module that names SlamConfig or reads a section of a configuration
    (`<x>.cfg.<section>` or `<x>.config.<section>`)."""
    out = []
    for cls in (n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)):
        for node in ast.walk(cls):
            if isinstance(node, ast.Name) and node.id == "SlamConfig":
                out.append(f"{cls.name} (line {node.lineno}): names SlamConfig")
            if isinstance(node, ast.Constant) and node.value == "SlamConfig":
                out.append(f"{cls.name} (line {node.lineno}): annotated SlamConfig")
            if (
                isinstance(node, ast.Attribute)
                and node.attr in SECTIONS
                and isinstance(node.value, (ast.Attribute, ast.Name))
                and getattr(node.value, "attr", getattr(node.value, "id", None))
                in ("cfg", "config")
            ):
                out.append(f"{cls.name} (line {node.lineno}): reads cfg.{node.attr}")
    return out


@pytest.mark.parametrize("path", _component_modules(), ids=lambda p: p.name)
def test_no_component_reads_the_whole_configuration(path):
    assert not _offences(ast.parse(path.read_text())), path.name


def test_the_check_finds_a_component_that_reads_the_configuration():
    """The check itself: a class that takes a SlamConfig, or reads a section of one, is
    found; one that takes its section's scalars is not."""
    bad = """
class Takes:
    def __init__(self, cfg: SlamConfig):
        self.cfg = cfg
class Reads:
    def __init__(self, c):
        self.gate = c.cfg.association.gate_prob
"""
    good = """
class Fine:
    def __init__(self, closure, gate_prob: float):
        self.cfg, self.gate = closure, gate_prob
        self.m = self.cfg.match_m
"""
    found = _offences(ast.parse(bad))
    assert any(s.startswith("Takes") for s in found) and any(s.startswith("Reads") for s in found)
    assert _offences(ast.parse(good)) == []

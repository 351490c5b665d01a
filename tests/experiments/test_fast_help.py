"""The first answers import no pydantic (issue 44): typer's value checks are built only for a
value given, and a left-out value still meets typer's own rules (a required argument)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from typer.testing import CliRunner

from experiments.cli import app

LIGHT = ("pydantic", "experiments.exec.choose", "multiprocessing")
_PROBE = """
import atexit, sys
atexit.register(lambda: print("LOADED", *[m for m in {light!r} if m in sys.modules]))
sys.argv = ["trunkslam", *{args!r}]
from experiments.cli import app
app()
"""


def _loaded(args: list[str], cwd) -> list[str]:
    code = _PROBE.format(light=LIGHT, args=args)
    res = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("LOADED"))
    return line.split()[1:]


@pytest.mark.slow
def test_the_preset_list_and_a_help_load_no_pydantic_and_no_executor(tmp_path):
    assert _loaded(["presets"], tmp_path) == []
    assert _loaded(["slam", "--help"], tmp_path) == []
    assert _loaded(["--threads", "2", "presets"], tmp_path) == ["pydantic"]  # a value to check


def test_a_left_out_value_still_meets_typers_rules():
    runner = CliRunner()
    res = runner.invoke(app, ["extract"])  # its INPUT is required
    assert res.exit_code == 2 and "Missing argument 'input'" in res.output, res.output
    res = runner.invoke(app, ["--threads", "0", "presets"])  # a given value is checked
    assert res.exit_code == 2 and "--threads" in res.output, res.output
    res = runner.invoke(app, ["presets"])  # --threads left out: None, as typer passes it
    assert res.exit_code == 0 and "victoria_park" in res.output, res.output

"""examples/tutorial.ipynb: committed without outputs, and run from top to bottom in a Jupyter
kernel of this interpreter (nbclient), where its scores are those the command line's own
scorers give for the same drive.

The kernel inherits this process's environment, so under pytest-xdist it reads the worker's
warm numba cache (tests/conftest.py); TMPDIR points it at the test's folder, where the
notebook's recording goes.
"""

from __future__ import annotations

import importlib.util
import re
import runpy
import shutil
import sys
from pathlib import Path

import nbformat
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
NOTEBOOK = REPO / "examples" / "tutorial.ipynb"
STRIP = REPO / "examples" / "strip_notebook.py"


def _code_cells(nb) -> list:
    return [c for c in nb.cells if c.cell_type == "code"]


def test_the_committed_notebook_holds_no_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    dirty = [
        i
        for i, c in enumerate(nb.cells)
        if c.cell_type == "code" and (c.outputs or c.execution_count is not None)
    ]
    assert not dirty, f"cells {dirty} hold outputs: run `make strip-notebooks`"
    assert set(nb.metadata) == {"kernelspec", "language_info"}, nb.metadata
    assert len(_code_cells(nb)) >= 8


def test_strip_leaves_the_committed_form(tmp_path, monkeypatch, capsys):
    """The stripper turns an executed-looking copy back into the committed file, byte for
    byte, and leaves the committed file alone."""
    nb = nbformat.read(NOTEBOOK, as_version=4)
    for n, cell in enumerate(_code_cells(nb), 1):
        cell.execution_count = n
        cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text="42\n")]
        cell.metadata["execution"] = {"iopub.status.busy": "2026-01-01T00:00:00Z"}
    nb.metadata["widgets"] = {"application/vnd.jupyter.widget-state+json": {"state": {}}}
    nb.metadata["language_info"] = {"name": "python", "version": "3.11.9"}
    copy = tmp_path / "executed.ipynb"
    nbformat.write(nb, copy)
    committed = tmp_path / "committed.ipynb"
    shutil.copy(NOTEBOOK, committed)
    monkeypatch.setattr(sys, "argv", [str(STRIP), str(copy), str(committed)])
    runpy.run_path(str(STRIP), run_name="__main__")
    assert capsys.readouterr().out == f"stripped {copy}\n"
    assert copy.read_bytes() == NOTEBOOK.read_bytes()
    assert committed.read_bytes() == NOTEBOOK.read_bytes()


def _stdout(cell) -> str:
    return "".join(o.get("text", "") for o in cell.outputs if o.output_type == "stream")


@pytest.mark.slow
def test_the_tutorial_runs_and_scores_as_the_cli(tmp_path, monkeypatch):
    from nbclient import NotebookClient

    from experiments.eval.poses import pose_errors
    from experiments.io.config_file import load_slam_config
    from experiments.pipeline.slam import reference_map_scores, summarise
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import interpolate_poses, run_slam
    from slam.smoother import SmootherOptions, problem_from_log, smooth

    monkeypatch.setenv("TMPDIR", str(tmp_path))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()  # a cell that raises fails the test (CellExecutionError)
    cells = _code_cells(nb)
    out = "\n".join(_stdout(c) for c in cells)
    figures = [c for c in cells if any("image/png" in o.get("data", {}) for o in c.outputs)]
    assert len(figures) == 2, out  # the scan and its features; the paths and maps
    widget = "application/vnd.jupyter.widget-view+json"
    assert any(widget in o.get("data", {}) for o in cells[-1].outputs), cells[-1].outputs
    rrd = Path(re.search(r"or: \.venv/bin/rerun (\S+)", out)[1])
    assert rrd.is_relative_to(tmp_path) and rrd.stat().st_size > 100_000

    # the same drive and run, scored as `trunkslam slam` scores it (summary.json, with
    # --reference-map of the scene's trees); the recording changes nothing in the run
    seq = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=240))
    log = run_slam(seq, load_slam_config("cycab"))
    summary = summarise(log, seq, 0.0)["truth"]
    trees = seq.truth_landmarks[:, :2]
    ref = reference_map_scores(log.landmark_xy, "trees", trees)
    ekf = re.search(r"EKF\s+ATE ([\d.]+) m \| NEES mean ([\d.]+)", out)
    assert ekf, out
    assert float(ekf[1]) == pytest.approx(summary["rmse_m"], abs=5e-5)  # printed to 4 decimals
    assert float(ekf[2]) == pytest.approx(summary["nees_mean"], abs=5e-3)
    printed = [float(v) for v in re.findall(r"GOSPA c = \d+ m: ([\d.]+) m", out)]
    assert len(printed) == 4, out  # EKF at 1 m and 20 m, then the smoothed map
    expected = [ref["gospa_1m"]["distance"], ref["gospa_20m"]["distance"]]
    np.testing.assert_allclose(printed[:2], expected, atol=5e-4)  # printed to 3 decimals

    sm = smooth(problem_from_log(log), SmootherOptions(solver="batch"))
    truth = interpolate_poses(log.scan_t, seq.truth_t, seq.truth_pose)
    ate = np.sqrt(np.mean(np.sum(pose_errors(sm.pose, truth)[:, :2] ** 2, axis=1)))
    smoothed = re.search(r"smoothed\s+ATE ([\d.]+) m", out)
    assert float(smoothed[1]) == pytest.approx(ate, abs=5e-5)
    chi2 = re.search(r"chi2 ([\d.]+) at the EKF's estimate -> ([\d.]+)", out)
    assert float(chi2[2]) < float(chi2[1])  # Levenberg-Marquardt never raises the cost
    assert float(chi2[2]) == pytest.approx(sm.chi2, abs=0.05)


def _notebook_hook():
    spec = importlib.util.spec_from_file_location("notebook_hook", REPO / "docs/hooks/notebook.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_docs_page_drops_the_widget_for_a_note():
    """docs/hooks/notebook.py: the widget's loader and state go, its view becomes the note,
    the rest stays; a page without exactly one of each is an error naming what is missing."""
    from mkdocs.exceptions import PluginError

    hook = _notebook_hook()
    loader = (
        "<script>\n(function() {\n  function addWidgetsRenderer() {\n"
        "    var s = 'https://unpkg.com/@jupyter-widgets/html-manager@*/dist/embed-amd.js';\n"
        "  }\n}());\n</script>"
    )
    state = '<script type="application/vnd.jupyter.widget-state+json">{"state": {}}</script>'
    view = '<script type="application/vnd.jupyter.widget-view+json">{"model_id": "x"}</script>'
    kept = "<pre>EKF      ATE 0.0250 m</pre>"
    html = f"{loader}<p>a</p>{kept}<div>{view}</div>{state}"
    assert hook.without_widgets(html) == f"<p>a</p>{kept}<div>{hook.VIEWER_NOTE}</div>"
    with pytest.raises(PluginError, match="expected one widget view, found 0"):
        hook.without_widgets(f"{loader}{kept}{state}")
    with pytest.raises(PluginError, match="expected one widget state, found 2"):
        hook.without_widgets(f"{loader}{state}{state}{view}")

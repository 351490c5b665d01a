"""Graph files (experiments/io/g2o.py, experiments/pipeline/graph.py): `export-graph` writes a
run's graph that GTSAM's own `readG2o` reads back to the same factors and values, and the
smoother solves GTSAM's shipped Victoria Park and cityTrees graphs to GTSAM's own batch error.
No shared data needed: the graphs are simulated or ship in the gtsam wheel."""

from __future__ import annotations

import math
import os

import gtsam
import numpy as np
import pytest
from graph_support import assert_same_graph
from typer.testing import CliRunner

from experiments.cli import app
from experiments.errors import DataError
from experiments.io.g2o import g2o_text, read_g2o
from experiments.io.run_log import read_run_log
from slam import se2
from slam.graph import graph_of_problem
from slam.smoother import SmootherOptions, smooth, solve_pose_graph

runner = CliRunner()


def _gtsam_batch(graph, values) -> tuple[float, int]:
    """GTSAM's own batch solve: Levenberg-Marquardt (default parameters) on readG2o's graph,
    with the same gauge prior as ours (sigma 1e-6 on the pose of lowest id at its value)."""
    k = min(k for k in values.keys() if gtsam.Symbol(k).chr() == 0)
    full = gtsam.NonlinearFactorGraph(graph)
    full.add(
        gtsam.PriorFactorPose2(k, values.atPose2(k), gtsam.noiseModel.Isotropic.Sigma(3, 1e-6))
    )
    opt = gtsam.LevenbergMarquardtOptimizer(full, values, gtsam.LevenbergMarquardtParams())
    return 2.0 * graph.error(opt.optimize()), int(opt.iterations())


@pytest.fixture(scope="module")
def simulated_run(tmp_path_factory):
    """A simulated 80-scan run with constant (uncorrelated) measurement noise: its graph file
    is the smoother's graph exactly but for the prior on the start."""
    tmp = tmp_path_factory.mktemp("graph_run")
    run = tmp / "run.npz"
    res = runner.invoke(app, ["simulate-drive", "--scans", "80", "--seed", "4", "--out", str(run)])
    assert res.exit_code == 0, res.output
    cfg = tmp / "constant.toml"
    cfg.write_text('[measurement]\nnoise = "constant"\n')
    out = tmp / "out"
    res = runner.invoke(app, ["slam", str(run), "--config", str(cfg), "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.slow
def test_readG2o_reads_an_exported_run_back_to_the_same_graph(simulated_run, tmp_path):
    path = tmp_path / "run.g2o"
    res = runner.invoke(app, ["export-graph", str(simulated_run), "--out", str(path)])
    assert res.exit_code == 0, res.output
    assert "correlation" not in res.output  # constant noise: nothing left out
    problem, _ = read_run_log(simulated_run)
    ours = read_g2o(path).graph
    graph, values = gtsam.readG2o(str(path), False)
    assert_same_graph(ours, graph, values)
    # the file is the run: one pose per scan (the laser's), an odometry factor between
    # consecutive scans, each measurement the filter used with its landmark as associated
    n, m = problem.n_scans, problem.n_measurements
    assert (ours.pose_id.size, ours.odo_from.size, ours.br_pose.size) == (n, n - 1, m)
    assert np.array_equal(ours.br_pose, problem.meas_scan)
    assert np.array_equal(ours.br_landmark, problem.meas_landmark)
    assert np.allclose(ours.br_range, problem.meas_z[:, 0], rtol=0, atol=0)
    assert np.allclose(ours.br_sigma[:, 1] ** 2, problem.meas_R[:, 0, 0], rtol=1e-15)
    laser = se2.compose(problem.init_pose[17], problem.laser_pose)
    assert np.allclose(ours.pose[17], laser, rtol=0, atol=1e-12)
    # solved, it is the smoother's solution: the same chi-square (its start prior has a
    # covariance of 1e-12, our gauge fix a sigma of 1e-6: both hold pose 0 where it is)
    r = solve_pose_graph(ours)
    s = smooth(problem, SmootherOptions(marginals=False))
    assert r.chi2 == pytest.approx(s.chi2, rel=1e-6)
    assert r.dof == s.dof
    lm = dict(zip(s.landmark_id.tolist(), s.landmark_xy))
    assert max(np.abs(lm[int(i)] - xy).max() for i, xy in zip(r.landmark_id, r.landmark_xy)) < 1e-6


@pytest.mark.slow
def test_export_notes_what_a_bearing_range_line_cannot_carry(simulated_run, tmp_path):
    """The default "fit" noise of the paper's extractor is correlated: the BR lines carry the
    marginal sigmas, and the command says how many measurements lost their correlation."""
    problem, _ = read_run_log(simulated_run)
    R = problem.meas_R.copy()
    R[:, 0, 1] = R[:, 1, 0] = 0.3 * np.sqrt(R[:, 0, 0] * R[:, 1, 1])
    g, correlated = graph_of_problem(type(problem)(**{**problem.arrays(), "meas_R": R}))
    assert correlated == problem.n_measurements
    assert np.allclose(g.br_sigma, np.sqrt(np.stack([R[:, 1, 1], R[:, 0, 0]], 1)))


@pytest.mark.slow
def test_export_graph_refuses_bad_places_and_formats(simulated_run, tmp_path):
    res = runner.invoke(app, ["export-graph", str(tmp_path / "nowhere"), "--out", "x.g2o"])
    assert res.exit_code == 1 and "not a folder" in res.output
    res = runner.invoke(app, ["export-graph", str(simulated_run), "--format", "toro"])
    assert res.exit_code == 2
    res = runner.invoke(
        app, ["export-graph", str(simulated_run), "--out", str(simulated_run / "g.g2o")]
    )
    assert res.exit_code == 1 and "inside the input folder" in res.output
    target = tmp_path / "target.g2o"
    target.write_text("keep")
    link = tmp_path / "link.g2o"
    os.symlink(target, link)
    res = runner.invoke(app, ["export-graph", str(simulated_run), "--out", str(link)])
    assert res.exit_code == 1 and "symbolic link" in res.output
    assert target.read_text() == "keep"


@pytest.mark.slow
def test_smooth_solves_an_exported_graph_file(simulated_run, tmp_path):
    path = tmp_path / "run.g2o"
    res = runner.invoke(app, ["export-graph", str(simulated_run), "--out", str(path)])
    res = runner.invoke(app, ["smooth", str(path)])
    assert res.exit_code == 0, res.output
    solved = tmp_path / "run_smoothed.g2o"
    assert "batch: chi2" in res.output and str(solved) in res.output
    before, after = read_g2o(path).graph, read_g2o(solved).graph
    # the same factors, the solved values: GTSAM finds nothing more to improve
    assert np.array_equal(before.br_range, after.br_range) and after.n_factors == before.n_factors
    graph, values = gtsam.readG2o(str(solved), False)
    chi2, _ = _gtsam_batch(graph, values)
    assert 2.0 * graph.error(values) == pytest.approx(chi2, rel=1e-6)
    res = runner.invoke(app, ["smooth", str(path), "--solver", "isam2", "--isam2-every", "10",
                              "--polish", "--out", str(tmp_path / "i.g2o")])  # fmt: skip
    assert res.exit_code == 0 and "isam2-chunks(10)+polish" in res.output
    res = runner.invoke(app, ["smooth", str(path), "--robust", "huber"])
    assert res.exit_code == 2 and "--robust" in res.output
    res = runner.invoke(app, ["smooth", str(path), "--measurements", "all"])
    assert res.exit_code == 2 and "--measurements" in res.output
    res = runner.invoke(app, ["smooth", str(simulated_run), "--skip-tag", "X"])
    assert res.exit_code == 2 and "graph file" in res.output


# ---- GTSAM's shipped graphs ---------------------------------------------------------------------


@pytest.mark.parametrize("name", ["victoriaPark_reduced_1k.g2o", "cityTrees_reduced_1k.g2o"])
def test_gtsam_reduced_graphs_read_and_solve_as_gtsam_does(name):
    """These files' landmark lines are LANDMARK2, a tag GTSAM's readG2o passes over (as every
    tag it does not know): read with that tag skipped, the graph is readG2o's, an odometry chain
    of 1000 poses. Solved, its error is zero to rounding for both (a chain has no conflict):
    there is no relative difference to speak of, so both are checked to be below 1e-12."""
    path = gtsam.findExampleDataFile(name)
    with pytest.raises(DataError, match=r"line \d+: unknown tag 'LANDMARK2'"):
        read_g2o(path)
    read = read_g2o(path, skip=("LANDMARK2",))
    assert read.skipped["LANDMARK2"] > 400
    graph, values = gtsam.readG2o(path, False)
    assert_same_graph(read.graph, graph, values)
    ours = solve_pose_graph(read.graph)
    theirs, _ = _gtsam_batch(graph, values)
    assert ours.n_factors == graph.size() == 999
    assert ours.chi2 < 1e-12 and theirs < 1e-12


@pytest.fixture(scope="module")
def victoria_park_head(tmp_path_factory) -> str:
    """The first 300 poses of GTSAM's victoria_park.txt (ODOMETRY and LANDMARK lines): the
    whole file's batch solve takes a minute and stops at 100 iterations unconverged."""
    lines = open(gtsam.findExampleDataFile("victoria_park.txt")).read().splitlines()
    keep = [ln for ln in lines if max(int(ln.split()[1]), int(ln.split()[2]) if
            ln.startswith("ODOMETRY") else 0) < 300]  # fmt: skip
    path = tmp_path_factory.mktemp("vp") / "victoria_park_300.txt"
    path.write_text("\n".join(keep) + "\n")
    return str(path)


@pytest.mark.slow
def test_victoria_park_txt_reads_as_readG2o_and_load2D_read_it():
    path = gtsam.findExampleDataFile("victoria_park.txt")
    graph, values = gtsam.readG2o(path, False)
    assert_same_graph(read_g2o(path).graph, graph, values)
    # load2D takes its ODOMETRY numbers for covariances (the zeros tell it): so do we when told
    graph, values = gtsam.load2D(path)
    assert_same_graph(read_g2o(path, edge_noise="covariance").graph, graph, values)


def test_victoria_park_solves_to_gtsams_own_batch_error(victoria_park_head):
    graph, values = gtsam.readG2o(victoria_park_head, False)
    read = read_g2o(victoria_park_head)
    assert_same_graph(read.graph, graph, values)
    theirs, iterations = _gtsam_batch(graph, values)
    ours = solve_pose_graph(read.graph, "batch")
    assert iterations < 100  # converged, not stopped
    assert ours.chi2 == pytest.approx(theirs, rel=1e-6)
    assert ours.initial_chi2 == pytest.approx(2.0 * graph.error(values), rel=1e-12)
    assert ours.chi2 < 1e-3 * ours.initial_chi2


@pytest.mark.parametrize(
    "text, message",
    [
        ("VERTEX_SE2 0 0 0 0\nFOO 1 2\n", r"line 2: unknown tag 'FOO'"),
        ("VERTEX_SE2 0 0 0\n", r"line 1: VERTEX_SE2 expects 4 numbers, got 3"),
        ("VERTEX_SE2 0 0 nan 0\n", r"line 1: VERTEX_SE2: NaN"),
        ("VERTEX_SE2 0 0 x 0\n", r"line 1: VERTEX_SE2: could not convert"),
        ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", r"line 2: VERTEX_SE2 0 given twice"),
        ("VERTEX_SE2 0.5 0 0 0\n", r"line 1: id 0.5 is not an integer"),
        ("VERTEX_SE2 0 0 0 0\nFIX 3\n", r"FIX 3: no such pose"),
        ("VERTEX_XY 0 0 0\n", r"no pose"),
        ("EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n", r"line 1: EDGE_SE2: not a positive definite info"),
        ("BR 0 1 0.1 5 0 0.1\n", r"line 1: BR: the range and standard deviations must be > 0"),
        ("BR 0 1 0.1 -5 1 0.1\n", r"line 1: BR: the range"),
    ],
)
def test_a_bad_graph_file_is_a_clear_error(tmp_path, text, message):
    path = tmp_path / "bad.g2o"
    path.write_text(text)
    with pytest.raises(DataError, match=message):
        read_g2o(path)


def test_smooth_names_an_unknown_tag_of_a_graph_file(tmp_path):
    path = tmp_path / "bad.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE3:QUAT 0 1\n")
    res = runner.invoke(app, ["smooth", str(path)])
    assert res.exit_code == 1 and "line 3: unknown tag 'EDGE_SE3:QUAT'" in res.output


def test_g2o_text_reads_back_exactly_and_fills_missing_values_as_readG2o(tmp_path):
    """Values the file does not give are filled as readG2o fills them, in file order."""
    path = tmp_path / "g.g2o"
    path.write_text(
        "EDGE_SE2 0 1 1 0 0.5 10 0 0 10 0 20\nBR 1 7 0.25 4 0.01 0.1\nLANDMARK 0 8 3 4 0.5 0 0.5\n"
    )
    read = read_g2o(path)
    graph, values = gtsam.readG2o(str(path), False)
    assert_same_graph(read.graph, graph, values)
    assert read.graph.br_sigma[1].tolist() == [math.sqrt(0.05), math.sqrt(0.5)]
    again = tmp_path / "again.g2o"
    again.write_text(g2o_text(read.graph))
    back = read_g2o(again).graph
    for name in read.graph.__dataclass_fields__:
        assert np.array_equal(getattr(back, name), getattr(read.graph, name)), name


def test_readG2o_reads_no_factor_after_a_comment(tmp_path):
    """Why `g2o_text` writes no comment (nor FIX): GTSAM's readG2o stops reading factors at
    one, though it still reads the vertices after it."""
    path = tmp_path / "c.g2o"
    edge = "1 0 0 1 0 0 1 0 1"
    path.write_text(
        f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 {edge}\n# a comment\n"
        f"VERTEX_SE2 2 2 0 0\nEDGE_SE2 1 2 {edge}\n"
    )
    graph, values = gtsam.readG2o(str(path), False)
    assert (graph.size(), values.size()) == (1, 3)
    assert read_g2o(path).graph.n_factors == 2


def test_a_graph_gtsam_cannot_solve_is_a_clear_error(tmp_path):
    """A landmark vertex no factor uses: GTSAM's iSAM2 raises (a key missing from its values);
    the command says so in one `error:` line, exit 1, no traceback."""
    path = tmp_path / "g.g2o"
    path.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_XY 7 5 5\n"
        "EDGE_SE2 0 1 1 0 0 100 0 0 100 0 100\n"
    )
    res = CliRunner().invoke(app, ["smooth", str(path), "--solver", "isam2"])
    assert res.exit_code == 1, res.output
    assert "GTSAM could not solve the problem" in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)

"""The executors (issue 13): the same seeded study gives the same numbers, bit for bit, in this
process, in 2 worker processes and on a Dask LocalCluster; so do the figures and recordings
made as trials, and `submit` (trials handed over without waiting); a trial that raises is
reported with its seed and the others are kept; trunkslam sweep."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from support import assert_tidy_tables, read_recording, recording_rows

from experiments.errors import ConfigError, ExperimentFailed
from experiments.exec import SerialExecutor, TrialsFailed, describe_seed, spawn_seeds
from experiments.exec.local import ProcessExecutor
from experiments.paper.association import rate_study
from experiments.paper.circles import pillar_monte_carlo, summarise, sweep_trial
from experiments.paper.products import figure_trial
from experiments.paper.reproduce import run_experiments
from experiments.paper.slam import Exp2Config, key_figures, monte_carlo
from experiments.paper.sweep import load_sweep, run_sweep, run_sweep_file
from experiments.sim.trajectory import CycabParams

distributed = pytest.importorskip("distributed", reason="dask[distributed] (trunkslam[dask])")


@pytest.fixture(scope="module")
def executors():
    """This process, 2 local worker processes, a Dask LocalCluster with 2 in-process workers."""
    from experiments.exec.cluster import DaskExecutor

    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    )
    client = distributed.Client(cluster)
    ex = {"serial": SerialExecutor(), "processes": ProcessExecutor(2), "dask": DaskExecutor(client)}
    yield ex
    for e in ex.values():
        e.close()
    client.close()
    cluster.close()


def blas_threads(cfg, seed) -> list[int]:
    """A trial: the thread counts of the BLAS libraries where it runs."""
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.mark.slow
def test_trials_in_this_process_use_one_blas_thread_as_the_workers_do(executors):
    """A multi-threaded BLAS rounds its sums differently (the full Victoria Park run's tables
    differed in their last digits between --workers 1 and 2): trials run with one BLAS thread
    wherever they run, and this process gets its own setting back afterwards."""
    from threadpoolctl import threadpool_info, threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):
        before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
        assert before and set(before) == {2}
        assert executors["serial"].map(blas_threads, [None], [None]) == [[1] * len(before)]
        assert executors["processes"].map(blas_threads, [None], [None]) == [[1] * len(before)]
        after = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
        assert after == before


def test_spawn_seeds_are_the_generators_spawn():
    """A study that drew run i as rng.spawn(R)[i] keeps its numbers with spawn_seeds."""
    old = [g.random(3) for g in np.random.default_rng(42).spawn(4)]
    new = [np.random.default_rng(s).random(3) for s in spawn_seeds(np.random.default_rng(42), 4)]
    for a, b in zip(old, new):
        assert np.array_equal(a, b)
    s = spawn_seeds(7, 3)[2]
    assert describe_seed(s) == "SeedSequence(entropy=7, spawn_key=(2,))"
    again = np.random.SeedSequence(7, spawn_key=(2,))  # the text rebuilds the seed
    assert np.random.default_rng(again).random() == np.random.default_rng(s).random()


@pytest.mark.slow
def test_pillar_study_identical_on_every_executor(executors):
    """Tables 1-2's Monte Carlo (8 draws at each of 6 positions): the same per-scan estimates
    and the same table figures, compared exactly."""
    got = {}
    for name, ex in executors.items():
        mc = pillar_monte_carlo(8, np.random.default_rng(5), executor=ex)
        got[name] = (mc.est, json.dumps(summarise(mc), sort_keys=True, default=str))
    ref = got["serial"]
    assert sum(len(v) for m in ref[0].values() for v in m.values()) > 50
    for name, (est, table) in got.items():
        assert est == ref[0], name
        assert table == ref[1], name


@pytest.mark.slow
def test_association_rates_identical_on_every_executor(executors):
    sweeps = {"clutter": ("clutter_per_scan", "clutter", [0.0, 20.0])}
    got = {}
    for name, ex in executors.items():
        rows = rate_study(np.random.default_rng(3), 3, sweeps=sweeps, executor=ex)
        got[name] = [{k: v for k, v in r.items() if k != "ms_per_scan"} for r in rows]
    assert len(got["serial"]) == 8 and got["serial"][0]["measurements"] > 0
    assert got["processes"] == got["serial"] and got["dask"] == got["serial"]


@pytest.mark.slow
def test_slam_study_identical_on_every_executor(executors):
    """Tables 3-4 and NEES of 2 short runs (with the smoother), every figure exactly equal."""
    cfg = Exp2Config(n_runs=2, cycab=CycabParams(n_scans=40), sensitivity=False)
    got = {}
    for name, ex in executors.items():
        res = monte_carlo(cfg, np.random.default_rng(11), executor=ex)
        got[name] = (key_figures(res), res.abs_err, res.nees, res.detected)
    ref = got["serial"]
    for name, (figs, err, nees, det) in got.items():
        assert figs == ref[0], name
        for m in cfg.methods:
            assert np.array_equal(err[m], ref[1][m]), name
            assert np.array_equal(nees[m], ref[2][m], equal_nan=True), name
            assert np.array_equal(det[m], ref[3][m]), name


@pytest.mark.slow
def test_reproduce_outputs_identical_with_1_and_2_workers_and_dask(tmp_path, executors):
    """`reproduce circle-sweep table1 --quick`: the tables (CSV bytes), the figures (PNG bytes,
    drawn as trials on the executor) and circles.rrd (made by a trial; compared row by row,
    rerun's row ids and log times aside) are the same on every executor."""
    out = {}
    for name, ex in executors.items():
        folder = tmp_path / name
        run_experiments(["circle-sweep", "table1"], folder, quick=True, seed=3, executor=ex)
        files = {p.name: p.read_bytes() for p in folder.iterdir() if p.suffix in (".csv", ".png")}
        out[name] = (files, recording_rows(folder / "circles.rrd"))
        m = json.loads((folder / "manifest.json").read_text())
        assert m["executor"]["executor"] == ex.name and not m["failed"]
    files, rec = out["serial"]
    assert files["circle_sweep.csv"].count(b"\n") > 60
    assert {"circle_sweep.png", "fig2a_scene.png", "fig3_position2.png"} <= set(files)
    assert {"circle_sweep.csv", "table1_ce.csv"} <= assert_tidy_tables(tmp_path / "serial")
    head = files["circle_sweep.csv"].decode().splitlines()[0]
    assert head == "sweep,sweep_value,method,rms_ce,rms_re,extracted_fraction"
    assert {"world/truth/pillars", "figures/laser/paper/circles"} <= {e.lstrip("/") for e in rec}
    for name in ("processes", "dask"):
        assert out[name][0].keys() == files.keys(), name
        for f, data in out[name][0].items():
            assert data == files[f], (name, f)
        assert out[name][1] == rec, name


@pytest.mark.slow
def test_submitted_trials_give_the_records_of_map(executors):
    """`submit` hands the trials over and returns their batch; this process can go on (here:
    other trials) before `result()`, which gives what `map` gives, and the same again when
    asked twice; a trial that raises is reported there; a cancelled batch has no result."""
    seeds = spawn_seeds(21, 3)
    ref = SerialExecutor().map(sweep_trial, [POINT] * 3, seeds)
    for name, ex in executors.items():
        batch = ex.submit(sweep_trial, [POINT] * 3, seeds, desc="submitted")
        meanwhile = ex.map(sweep_trial, [POINT], seeds[:1])
        calls: list = []
        got = batch.result(lambda *call, calls=calls: calls.append(call))
        assert repr(got) == repr(ref) and repr(meanwhile[0]) == repr(ref[0]), name
        assert calls[0] == ("submitted", 0, 3) and calls[-1] == ("submitted", 3, 3), name
        assert batch.result() is got
        bad = ex.submit(sweep_trial, [POINT, dict(POINT, radius_m=-0.3)], seeds[:2], desc="bad")
        with pytest.raises(TrialsFailed) as info:
            bad.result()
        assert [f.index for f in info.value.failures] == [1], name
        assert repr(info.value.records[0]) == repr(ref[0]), name
        dropped = ex.submit(sweep_trial, [POINT], seeds[:1], desc="dropped")
        dropped.cancel()
        with pytest.raises(RuntimeError, match="cancelled"):
            dropped.result()


@pytest.mark.slow
def test_figures_drawn_on_every_executor_are_the_files_drawn_here(tmp_path, executors):
    """A figure drawn as a trial (`figure_trial`: in this process, in a worker process, on a
    Dask worker) is byte for byte the PNG file its plot function writes here."""
    from experiments.paper import circles_figures, slam_figures

    rng = np.random.default_rng(4)
    pts = rng.normal(size=(200, 2)) * 4.0
    sig = np.abs(rng.normal(size=(30, 3)))
    series = [{"label": "a", "scan": np.arange(30), "err": rng.normal(size=(30, 3)), "sigma": sig}]
    specs = [
        ("raw.png", circles_figures.plot_raw_scan, (pts, "a scan"), {}),
        ("errors.png", slam_figures.plot_pose_errors, (series, "errors"), {}),
    ]
    circles_figures.plot_raw_scan(pts, "a scan", tmp_path / "raw.png")
    slam_figures.plot_pose_errors(series, "errors", tmp_path / "errors.png")
    for name, ex in executors.items():
        got = ex.map(figure_trial, specs, chunksize=1)
        assert [list(files) for files in got] == [["raw.png"], ["errors.png"]], name
        for files in got:
            for f, data in files.items():
                assert data.startswith(b"\x89PNG") and data == (tmp_path / f).read_bytes(), name


@pytest.mark.slow
def test_recordings_made_on_every_executor_hold_what_one_made_here_holds(tmp_path, executors):
    """circles.rrd and the pillar court's figures made by a trial (`products_trial`, which
    records with a `MemoryRecorder`) on every executor: the figures are byte for byte, and the
    recording row for row (with its layout), those made here with a `Recorder` writing a file."""
    from experiments.paper.circles import log_first_draws, pillar_figures, products_trial
    from experiments.render.viz import Recorder

    seeds = spawn_seeds(8, 7)
    job = (("paper", "bailey"), 0.01, tuple(seeds[:6]))
    with Recorder(tmp_path / "here.rrd", "circles") as rec:
        log_first_draws(rec, job[0], job[1], list(job[2]))
        here = pillar_figures(np.random.default_rng(seeds[6]), rec)

    def layout(path) -> dict:  # the views in a set: the blueprint's ids are random
        return {**read_recording(path), "views": sorted(read_recording(path)["views"])}

    rows, views = recording_rows(tmp_path / "here.rrd"), layout(tmp_path / "here.rrd")
    assert sum(len(v) for v in rows.values()) > 50 and len(here) == 4
    for name, ex in executors.items():
        [files] = ex.map(products_trial, [job], [seeds[6]])
        (tmp_path / f"{name}.rrd").write_bytes(files.pop("circles.rrd"))
        assert recording_rows(tmp_path / f"{name}.rrd") == rows, name
        assert layout(tmp_path / f"{name}.rrd") == views, name
        assert files == here, name


@pytest.mark.slow
def test_a_deferred_part_that_fails_fails_its_experiment(tmp_path, monkeypatch):
    """The circle sweep's figure is drawn after the experiments (`RunContext.later`); when that
    raises a project error, circle-sweep is listed as failed with it, its files (the table,
    written earlier) and configuration are removed, and the other experiment is kept."""
    from experiments.errors import DataError
    from experiments.paper import circles_figures

    def broken(*args, **kwargs):
        raise DataError("no room for the figure (test)")

    monkeypatch.setattr(circles_figures, "plot_sweep", broken)
    with pytest.raises(ExperimentFailed, match="circle-sweep"):
        run_experiments(["circle-sweep", "noise-calibration"], tmp_path / "r", quick=True)
    m = json.loads((tmp_path / "r" / "manifest.json").read_text())
    assert "no room for the figure (test)" in m["failed"]["circle-sweep"]
    assert not [f for f in m["outputs"] if f.startswith("circle_sweep")]
    assert "circle-sweep" not in m["config"] and "circle-sweep" not in m["seconds"]
    assert "noise_calibration.csv" in m["outputs"] and "noise-calibration" in m["seconds"]


POINT = {"range_m": 10.0, "radius_m": 0.3, "noise_m": 0.01, "n_trials": 2}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["serial", "processes", "dask"])
def test_a_trial_that_raises_is_reported_with_its_seed(executors, name):
    """Trial 1 of 3 has a negative radius (the scene refuses it): the error names trial 1 and
    its seed, and the records of trials 0 and 2 are those of a clean run."""
    bad = dict(POINT, radius_m=-0.3)
    seeds = spawn_seeds(99, 3)
    with pytest.raises(TrialsFailed) as info:
        executors[name].map(sweep_trial, [POINT, bad, POINT], seeds, desc="sweep test")
    exc = info.value
    assert [f.index for f in exc.failures] == [1]
    assert (
        exc.failures[0].seed
        == describe_seed(seeds[1])
        == ("SeedSequence(entropy=99, spawn_key=(1,))")
    )
    assert "trial 1 (seed SeedSequence(entropy=99, spawn_key=(1,)))" in str(exc)
    clean = SerialExecutor().map(sweep_trial, [POINT, POINT, POINT], seeds)
    assert exc.records[1] is None
    assert repr(exc.records[0]) == repr(clean[0]) and repr(exc.records[2]) == repr(clean[2])


@pytest.mark.slow
def test_a_failed_trial_fails_its_experiment_with_its_seed(tmp_path, monkeypatch):
    """In `reproduce`, the experiment is listed as failed with the trial's seed; the other
    experiments' results are written."""
    import experiments.paper.circles as circles

    real = circles.sweep_point

    def flaky(rng, range_m, radius_m, noise_m, n_trials, methods=circles.METHODS):
        if range_m == 15.0:
            raise ConfigError("range 15 m refused (test)")
        return real(rng, range_m, radius_m, noise_m, n_trials, methods)

    monkeypatch.setattr(circles, "sweep_point", flaky)
    with pytest.raises(ExperimentFailed, match="circle-sweep"):
        run_experiments(["circle-sweep", "noise-calibration"], tmp_path / "r", quick=True)
    m = json.loads((tmp_path / "r" / "manifest.json").read_text())
    why = m["failed"]["circle-sweep"]
    assert "trial 4 (seed SeedSequence(entropy=" in why and "spawn_key=(4,)" in why
    assert "range 15 m refused" in why
    assert "noise_calibration.csv" in m["outputs"]


SWEEP = """
study = "association"
trials = 3
seed = 1
[base]
"sim.n_scans" = 4
[grid]
gate_prob = [0.9, 0.999]
"sim.clutter_per_scan" = [0.0, 20.0]
"""


@pytest.mark.slow
def test_sweep_writes_a_tidy_csv_and_a_plot_per_field(tmp_path, executors):
    path = tmp_path / "s.toml"
    path.write_text(SWEEP)
    spec = load_sweep(path)
    assert len(spec.points) == 4 and spec.swept == ["gate_prob", "sim.clutter_per_scan"]
    assert (
        spec.points[3]["sim"]["clutter_per_scan"] == 20.0 and spec.points[3]["sim"]["n_scans"] == 4
    )
    files, failed = run_sweep(spec, tmp_path / "a", executors["serial"])
    assert not failed
    names = sorted(p.name for p in files)
    assert names == [
        "sweep.csv",
        "sweep.json",
        "sweep_gate_prob.png",
        "sweep_sim.clutter_per_scan.png",
    ]
    rows = list(csv.DictReader((tmp_path / "a" / "sweep.csv").open()))
    assert list(rows[0]) == ["point", *spec.swept, "method", "metric", "mean", "std", "n"]
    # 4 points x 4 methods x 4 metrics, 3 trials each
    assert len(rows) == 64 and {r["n"] for r in rows} == {"3"}
    nn = {
        (r["gate_prob"], r["sim.clutter_per_scan"]): float(r["mean"])
        for r in rows
        if r["method"] == "nn" and r["metric"] == "correct_rate"
    }
    assert all(0 <= v <= 1 for v in nn.values())
    # the same sweep on Dask: the same table but for the wall times
    run_sweep(spec, tmp_path / "b", executors["dask"])
    rows_b = list(csv.DictReader((tmp_path / "b" / "sweep.csv").open()))
    strip = [r for r in rows if r["metric"] != "ms_per_scan"]
    assert strip == [r for r in rows_b if r["metric"] != "ms_per_scan"]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('study = "nope"\n[grid]\nx = [1]', "unknown study 'nope'"),
        ('study = "association"\n[grid]\n"sim.clutter" = [1.0]', "'sim.clutter' is not a field"),
        ('study = "association"\n[grid]\ngate_prob = 0.9', "grid.gate_prob must be a non-empty"),
        ('study = "association"\n[grid]\n"sim.p_detect" = ["a"]', "p_detect"),
        ('study = "association"\ntrials = 0\n[grid]\ngate_prob = [0.9]', "trials must be"),
        ('study = "circles"', "give either [grid] or [[points]], not neither"),
        ('study = "circles"\n[grid]\nnoise_m = [-0.01]', "must be positive"),
    ],
)
def test_sweep_file_errors_name_the_key(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=None) as info:
        load_sweep(path)
    assert message in str(info.value) and str(path) in str(info.value)


@pytest.mark.slow
def test_sweep_keeps_the_other_trials_when_one_fails(tmp_path, monkeypatch):
    """A point whose trials fail (a failure no check before the trials can foresee: here the
    simulation itself raising on one scene; a wrong scene name is refused before any trial,
    tests/experiments/test_hostile_files.py): its trials are reported with their seeds in
    sweep.json, the other point's rows are written, the command fails."""
    import experiments.paper.slam as exp2
    from experiments.errors import DataError

    simulate = exp2.simulate_cycab_run

    def breaks_on_the_yard(rng, scene, params):
        if scene == "test_yard":
            raise DataError("the simulated drive broke")
        return simulate(rng, scene, params)

    monkeypatch.setattr(exp2, "simulate_cycab_run", breaks_on_the_yard)  # workers=1: in process
    path = tmp_path / "s.toml"
    path.write_text(
        'study = "slam"\ntrials = 2\n[base]\nmethods = ["bailey"]\n"cycab.n_scans" = 15\n'
        '[[points]]\nscene = "tree_park"\n[[points]]\nscene = "test_yard"\n'
    )  # the second point fails in its trials
    with pytest.raises(ExperimentFailed, match=r"trial\(s\) of the sweep failed"):
        run_sweep_file(path, tmp_path / "out", workers=1)
    summary = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert [(f["point"], f["trial"]) for f in summary["failed"]] == [(1, 0), (1, 1)]
    assert summary["failed"][0]["seed"].startswith("SeedSequence(entropy=")
    rows = list(csv.DictReader((tmp_path / "out" / "sweep.csv").open()))
    assert {r["point"] for r in rows} == {"0"} and rows[0]["n"] == "2"


def test_example_sweep_files_parse():
    from pathlib import Path

    files = sorted((Path(__file__).resolve().parents[2] / "datasets" / "sweeps").glob("sweep_*"))
    assert len(files) >= 3
    for f in files:
        spec = load_sweep(f)
        assert spec.points and spec.trials >= 1


def test_cli_study_choices_are_the_studies():
    from experiments.cli import Study
    from experiments.paper.sweep import STUDIES

    assert [s.value for s in Study] == list(STUDIES)

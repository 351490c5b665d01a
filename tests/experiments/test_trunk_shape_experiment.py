"""Experiment `trunk-shape` (experiments/paper/trunk_shape.py): its calibration drives and one
run, on the quick study."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.exec import spawn_seeds
from experiments.paper import trunk_shape as ts


@pytest.mark.slow
def test_oval_trunks_give_correlated_offsets_and_a_white_filter_out_of_its_bounds():
    seeds = spawn_seeds(np.random.default_rng(3), 2)
    cfgs = {name: ts.shape_config(shape, 1, quick=True) for name, shape in ts.SHAPES.items()}
    cal = [ts.calibration_trial((name, cfg), s) for name, cfg in cfgs.items() for s in seeds]
    # a seed used twice in one process gives the same drive (its SeedSequence is copied)
    again = ts.calibration_trial(("oval", cfgs["oval"]), seeds[0])
    first = cal[len(seeds)]["sightings"]["paper"]["offset"]
    assert np.array_equal(again["sightings"]["paper"]["offset"], first)
    truth = {name: ts.truth_pass_sd(cal, name) for name in cfgs}
    for m in ts.METHODS:
        assert max(truth["circle"][m]) < 0.015  # circles: white errors
        assert truth["oval"][m][0] > 0.05 and truth["oval"][m][1] > 0.02
    crit = ts.criterion_sd(cal, "oval")
    assert all(len(v) == 2 and min(v) >= 0 for v in crit.values())
    records = []
    for name, cfg in cfgs.items():
        for model in ts.MODELS[:2]:
            sd = {m: truth[name][m] for m in ts.METHODS}
            by = {m: ts._model_config(cfg, m, model, sd[m]) for m in ts.METHODS}
            records.append(ts.shape_trial((name, model, by, 0), seeds[0]))
    rows = {(r["shape"], r["method"], r["model"]): r for r in ts.summary(records)}
    assert len(rows) == 2 * len(ts.METHODS) * 2
    for m in ts.METHODS:
        oval, circle = rows[("oval", m, "white")], rows[("circle", m, "white")]
        assert oval["range_lag1"] > 0.5 and circle["range_lag1"] < 0.3
        assert oval["nees_mean"] > 3 * circle["nees_mean"]
        model = rows[("oval", m, ts.MODELS[1])]
        assert model["model_range_sd_m"] == truth["oval"][m][0]
        assert model["nees_mean"] < oval["nees_mean"]


def test_each_model_sets_the_offset_and_how_the_filter_carries_it():
    cfg = ts.shape_config(ts.SHAPES["oval"], 1, quick=True)
    want = {
        "white": ((0.0, 0.0), "inflation"),
        "pass offset, truth's s": ((0.08, 0.04), "inflation"),
        "pass offset, criterion's s": ((0.08, 0.04), "inflation"),
        "pass offset as a state, truth's s": ((0.08, 0.04), "state"),
        "pass offset as a state, criterion's s": ((0.08, 0.04), "state"),
    }
    assert set(want) == set(ts.MODELS)
    for model, (sd, kind) in want.items():
        got = ts._model_config(cfg, "paper", model, (0.08, 0.04))
        assert got.methods == ("paper",)
        assert got.slam.measurement.pass_offset_sd_m == sd
        assert got.slam.measurement.pass_offset_model == kind

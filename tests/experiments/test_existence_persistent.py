"""Map policy "existence" against persistent clutter (`map_policy.existence_clutter =
"persistent"`, `slam.existence`): its settings derived from a run without the truth
(`experiments.eval.existence_rates.derive_persistent`), and what it does in the simulated park
with clutter, where the truth is exact."""

import numpy as np
import pytest

from experiments.errors import DataError
from experiments.eval.existence_rates import (
    derive_existence,
    derive_persistent,
    truncated_geometric_p,
)
from experiments.paper.sim_clutter import _map_figures
from slam import run_slam
from tests.experiments.test_existence_policy_run import clutter_drive


@pytest.mark.parametrize(("p", "cut"), [(0.3, 2), (0.6, 5)])
def test_the_truncated_geometric_estimate_recovers_a_known_repeat_probability(p, cut):
    """Runs k drawn geometric (P(k) = p^(k-1) (1 - p)) and kept when k <= cut: the estimate is
    within 4 standard errors of p (binomial-like, sqrt(p (1 - p) / n) bounds it for n runs)."""
    rng = np.random.default_rng(7)
    k = rng.geometric(1 - p, size=40000)
    k = k[k <= cut]
    got = truncated_geometric_p(k, cut)
    assert abs(got - p) < 4 * np.sqrt(p * (1 - p) / k.size)


def test_the_truncated_geometric_estimate_refuses_runs_outside_its_range():
    with pytest.raises(DataError, match="truncated_geometric_p"):
        truncated_geometric_p(np.array([1, 3]), 2)
    assert truncated_geometric_p(np.ones(9), 2) == 0.05  # none seen again: 0.5 / (9 + 1)
    assert truncated_geometric_p(np.zeros(0), 2) == 0.5  # a clean park: nothing measured


@pytest.fixture(scope="module")
def drive():
    scene, seq, cfg, feats = clutter_drive()
    return scene, seq, cfg, feats, run_slam(seq, cfg, features=feats)


def test_the_persistent_settings_come_from_the_tracks_that_never_joined(drive):
    """repeat_prob is the truncated estimate of the never-mapped tracks' runs (confirm_scans 3:
    runs of 1 or 2 scans), and those tracks are the ones the run did not map."""
    _, seq, cfg, _, lg = drive
    d = derive_persistent(lg, (0, seq.n_scans))
    runs = d["never_mapped_runs"]
    assert len(runs) == cfg.map_policy.confirm_scans - 1 and sum(runs) == d["never_mapped_tracks"]
    assert d["clipped_tracks"] == 0  # a single-scan confirm run: no track past confirm_scans - 1
    k = np.repeat(np.arange(1, len(runs) + 1), runs)
    s = d["settings"]
    assert s["map_policy.existence_repeat_prob"] == truncated_geometric_p(k, len(runs))
    assert 0 < s["map_policy.existence_repeat_prob"] < 1
    assert s["map_policy.existence_shape_sd_m"] >= 0 and d["consecutive_pairs"] <= runs[1]
    never = set(lg.meas_track[lg.meas_track >= 0].tolist()) - set(lg.landmark_id.tolist())
    assert d["never_mapped_tracks"] == len(never)


def test_persistent_clutter_maps_the_trunks_and_not_the_legs_or_bushes_seen_a_few_times(drive):
    """The drive of seed 3 (the uniform clutter maps a leg or a bush there): with persistent
    clutter, settings derived from the confirm run, every trunk is mapped and nothing else."""
    scene, seq, cfg, feats, lg = drive
    settings = derive_existence(lg, seq, (0, seq.n_scans))["settings"]
    settings |= derive_persistent(lg, (0, seq.n_scans))["settings"]
    ex = cfg.with_(**{"map_policy.policy": "existence", **settings})
    uniform = _map_figures(run_slam(seq, ex, features=feats), scene, seq, feats)
    per = ex.with_(**{"map_policy.existence_clutter": "persistent"})
    f = _map_figures(run_slam(seq, per, features=feats), scene, seq, feats)
    assert uniform["landmarks"] > uniform["right"]  # the case the model is for
    assert f["trunks_found"] == f["trunks"] and f["right"] == f["landmarks"]


def test_the_uniform_clutter_ignores_the_persistent_settings(drive):
    _, seq, cfg, feats, _ = drive
    ex = cfg.with_(**{"map_policy.policy": "existence"})
    a = run_slam(seq, ex, features=feats)
    b = run_slam(
        seq,
        ex.with_(**{"map_policy.existence_repeat_prob": 0.2, "map_policy.existence_shape_sd_m": 1}),
        features=feats,
    )
    np.testing.assert_array_equal(a.landmark_xy, b.landmark_xy)
    np.testing.assert_array_equal(a.landmark_existence, b.landmark_existence)

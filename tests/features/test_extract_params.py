"""`extract_features` takes an `ExtractorParams` (the form a setting keeps from the
configuration to the kernel), with keyword overrides still accepted."""

from __future__ import annotations

import math

import numpy as np
import pytest

from features import ExtractorParams, FeaturesError, Scan, extract_features
from features.bailey import BaileyParams
from slam import SlamConfig

GAMMA = math.radians(0.5)


def _scan(seed: int) -> Scan:
    """A wall and a few trunks, with range noise and no-returns."""
    rng = np.random.default_rng(seed)
    angles = -math.pi / 2 + GAMMA * np.arange(361)
    r = np.full(361, 25.0)
    for cx, cy, rad in rng.uniform([2, -8, 0.05], [15, 8, 0.4], size=(6, 3)):
        dx, dy = np.cos(angles), np.sin(angles)
        b = dx * cx + dy * cy
        disc = b * b - (cx * cx + cy * cy - rad * rad)
        hit = np.where(disc >= 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
        r = np.minimum(r, np.where(hit > 0, hit, np.inf))
    r = r + rng.normal(0, 0.01, r.size)
    return Scan(r, -math.pi / 2, GAMMA, max_range_m=50.0)


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.circle_params, b.circle_params)
    np.testing.assert_array_equal(a.circle_cov, b.circle_cov)
    assert a.n_circles == b.n_circles


@pytest.mark.parametrize("seed", range(4))
def test_params_give_what_the_same_keywords_give(seed):
    scan = _scan(seed)
    p = ExtractorParams(short_trunks=False, sigma_r_m=0.015)
    for method in ("paper", "geometric"):
        by_params = extract_features(scan, method, p)
        _same(by_params, extract_features(scan, method, **p.to_dict()))
        _same(extract_features(scan, method, ExtractorParams()), extract_features(scan, method))
        # an override replaces one field of the params
        over = extract_features(
            scan, method, ExtractorParams(), short_trunks=False, sigma_r_m=0.015
        )
        _same(over, by_params)
    assert any(extract_features(_scan(s), "paper").n_circles for s in range(4))


def test_the_run_passes_its_extractor_params_as_they_are():
    cfg = SlamConfig().with_(**{"features.extractor.short_trunks": False})
    params, options = cfg.features.extractor_args()
    assert params is cfg.features.extractor and options == {}
    bailey = cfg.with_(**{"features.method": "bailey"}).features
    params, options = bailey.extractor_args()
    assert isinstance(params, BaileyParams) and set(options) == {
        "range_sigma_m",
        "range_sigma_per_m",
        "bearing_sigma_rad",
        "radius_sigma_m",
    }
    scan = _scan(0)
    _same(
        extract_features(scan, "bailey", params, **options),
        extract_features(scan, "bailey", **bailey.extractor_kwargs()),
    )


def test_wrong_params_are_named():
    scan = _scan(0)
    with pytest.raises(FeaturesError, match="params: expected a features.ExtractorParams"):
        extract_features(scan, "paper", {"sigma_r_m": 0.01})
    with pytest.raises(FeaturesError, match="unknown extractor parameter"):
        extract_features(scan, "paper", ExtractorParams(), sigma_rm=0.01)
    with pytest.raises(FeaturesError, match="sigma_r_m"):
        extract_features(scan, "paper", ExtractorParams(), sigma_r_m=-1.0)

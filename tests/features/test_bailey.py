"""The Victoria Park baseline detector: the published detections, known trunks, each rule,
the laser-frame adapter, and hostile input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import features.bailey as bailey
from features import extract_features
from features.bailey import BAILEY_BEAM_RAD, BaileyParams, detect_trees, extract_bailey
from features.types import KIND_CIRCLE, KIND_CLUTTER, Scan

BEAM = BAILEY_BEAM_RAD
ANGLES = np.arange(361) * math.pi / 360


def cast(angles: np.ndarray, circles) -> np.ndarray:
    """Exact ranges from the origin to circles (x, y, r); NaN where nothing is hit."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    best = np.full(angles.size, np.nan)
    for cx, cy, rad in circles:
        b = d @ np.array([cx, cy])
        disc = b * b - (cx * cx + cy * cy - rad * rad)
        with np.errstate(invalid="ignore"):
            t = b - np.sqrt(disc)
        hit = (disc >= 0) & (t > 0) & ~(t >= best)
        best = np.where(hit, t, best)
    return best


def trunk_at(range_m: float, bearing_rad: float, radius_m: float):
    return (range_m * math.cos(bearing_rad), range_m * math.sin(bearing_rad), radius_m)


def empty_scan() -> np.ndarray:
    return np.full(361, np.nan)


# ---- the published detections ----------------------------------------------------------------


@pytest.fixture(scope="module")
def vp_reference(vp_dir):
    from experiments.io.victoria_park import load_raw_sick_ranges, load_reference_detections

    _, zt = load_reference_detections(vp_dir)
    return (
        load_raw_sick_ranges(vp_dir, no_return_as_nan=False),  # the original's input
        load_raw_sick_ranges(vp_dir),  # no return as NaN
        zt[:2000],
    )


@pytest.mark.data
def test_reproduces_all_2000_published_scans(vp_reference):
    masked, with_nan, zt = vp_reference
    n_det = 0
    for k in range(2000):
        ref = zt[k]
        for ranges in (masked[k], with_nan[k]):
            out = detect_trees(ranges)
            assert out.shape == ref.shape, f"scan {k + 1}: {out.shape[1]} vs {ref.shape[1]}"
            np.testing.assert_allclose(out, ref, rtol=0, atol=1e-6, err_msg=f"scan {k + 1}")
        n_det += ref.shape[1]
    assert n_det == 17117  # detections in zt{1..2000}; every one matched


@pytest.mark.data
def test_numba_kernel_equals_numpy_twin_on_real_scans(vp_reference):
    _, with_nan, _ = vp_reference
    for k in range(2000):
        a = bailey._detect(with_nan[k], None, bailey._DEFAULT, bailey._kernel_numba)
        b = bailey._detect(with_nan[k], None, bailey._DEFAULT, bailey._kernel_numpy)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y, err_msg=f"scan {k + 1}")


@pytest.mark.data
def test_adapter_on_real_scans_is_detect_trees_in_the_laser_frame(vp_dir, vp_reference):
    from experiments.io.victoria_park import load_victoria_park

    seq = load_victoria_park(vp_dir, n_scans=300)
    _, _, zt = vp_reference
    for k in range(seq.n_scans):
        f = extract_bailey(seq.scan(k))
        ref = zt[k]
        assert f.n_circles == ref.shape[1]
        bearing_laser = -math.pi / 2 + ref[1]  # 0..pi from the right -> laser frame
        np.testing.assert_allclose(f.circle_params[:, 0], ref[0] * np.cos(bearing_laser), atol=1e-6)
        np.testing.assert_allclose(f.circle_params[:, 1], ref[0] * np.sin(bearing_laser), atol=1e-6)
        np.testing.assert_allclose(f.circle_params[:, 2], ref[2] / 2, atol=1e-6)
        # The detection's beams: its bearing is the midpoint of its first and last beam.
        np.testing.assert_allclose(f.circle_beams.sum(axis=1) * BEAM / 2, ref[1], atol=1e-9)
        assert np.count_nonzero(f.segment_kind == KIND_CIRCLE) == f.n_circles


# ---- known trunks ----------------------------------------------------------------------------


def test_hand_made_trunk_gives_the_hand_computed_numbers():
    r = empty_scan()
    r[178:183] = [9.90, 9.82, 9.80, 9.82, 9.90]  # a trunk's front face straight ahead
    out = detect_trees(r)
    assert out.shape == (3, 1)
    d = 5 * BEAM * 9.90  # (A_end - A_start + one beam) * mean edge range
    assert out[2, 0] == pytest.approx(d, abs=1e-12)
    assert out[0, 0] == pytest.approx(9.80 + d / 2, abs=1e-12)  # middle beam + radius
    assert out[1, 0] == pytest.approx(math.pi / 2, abs=1e-12)  # midpoint of the edge beams


def test_even_beam_count_averages_the_two_middle_beams():
    r = empty_scan()
    r[100:104] = [12.00, 11.90, 11.86, 12.02]
    out = detect_trees(r)
    d = (103 - 100 + 1) * BEAM * (12.00 + 12.02) / 2
    expected = [(11.90 + 11.86) / 2 + d / 2, 101.5 * BEAM, d]
    np.testing.assert_allclose(out[:, 0], expected, atol=1e-12)


@pytest.mark.parametrize(
    "range_m, bearing_rad, radius_m",
    [(5.0, 1.0, 0.2), (10.0, math.radians(60), 0.25), (20.0, 2.0, 0.4), (15.0, 1.5, 0.15)],
)
def test_ray_cast_trunk_is_found_within_beam_quantisation(range_m, bearing_rad, radius_m):
    out = detect_trees(cast(ANGLES, [trunk_at(range_m, bearing_rad, radius_m)]))
    assert out.shape == (3, 1)
    # Measured errors: range <= 0.046 m, bearing <= 0.0036 rad, diameter <= 0.091 m.
    assert abs(out[1, 0] - bearing_rad) <= BEAM / 2
    assert abs(out[0, 0] - range_m) <= range_m * BEAM / 2
    assert abs(out[2, 0] - 2 * radius_m) <= range_m * BEAM


# ---- one rule at a time ----------------------------------------------------------------------


def _trunk_scan(**extra) -> np.ndarray:
    r = empty_scan()
    r[178:183] = [9.90, 9.82, 9.80, 9.82, 9.90]
    for beams, value in extra.items():
        lo, hi = map(int, beams[1:].split("_"))
        r[lo : hi + 1] = value
    return r


def test_isolation_removes_a_trunk_near_another_segment():
    assert detect_trees(_trunk_scan()).shape[1] == 1
    # A segment 4 beams after the trunk and 2 m farther: a break, but its start lies ~2.0 m
    # from the trunk's end (< 3 m), so both go.
    assert detect_trees(_trunk_scan(b186_190=11.9)).shape[1] == 0
    # 40 beams (20 deg) later at the same range: 3.4 m away, both stay.
    assert detect_trees(_trunk_scan(b222_226=9.9)).shape[1] == 2


def test_isolation_looks_three_segments_ahead_only():
    def scan(n_between: int) -> np.ndarray:
        r = empty_scan()
        r[100:104] = 9.9  # segment 0, a trunk
        far = [106, 109, 112][:n_between]  # isolated single beams at 30, 45, 60 m
        r[far] = [30.0, 45.0, 60.0][:n_between]
        start = 103 + 3 * (n_between + 1)
        r[start : start + 4] = 9.9  # ~1 m from segment 0's end
        return r

    def kept_trunk(r):
        return bool(np.any(np.isclose(detect_trees(r)[1], 101.5 * BEAM)))

    assert not kept_trunk(scan(2))  # the close segment is 3 segments ahead: tested
    assert kept_trunk(scan(3))  # 4 segments ahead: not tested, the trunk stays


def test_occlusion_removes_the_farther_of_two_adjacent_segments():
    r = _trunk_scan()
    r[185] = 40.0  # 3 beams after the trunk's end: not adjacent (1.5 deg >= 1 deg)
    out = detect_trees(r)
    assert out.shape[1] == 2
    r = _trunk_scan()
    r[184] = 40.0  # 2 beams after: on the 1-deg threshold; 182 -> 184 rounds below it
    assert ANGLES[184] - ANGLES[182] < 2 * math.pi / 360
    out = detect_trees(r)
    assert out.shape[1] == 1 and out[1, 0] == pytest.approx(math.pi / 2)  # the far one went
    r = _trunk_scan()
    r[183] = 40.0  # directly adjacent
    out = detect_trees(r)
    assert out.shape[1] == 1 and out[1, 0] == pytest.approx(math.pi / 2)


def test_occlusion_removes_the_trunk_when_it_is_the_farther_one():
    r = _trunk_scan()
    r[183:260] = 5.0  # a long arc-shaped wall in front, right after the trunk
    assert detect_trees(r).shape[1] == 0  # trunk occluded; the wall fails the chord test
    r[183] = np.nan
    r[184] = np.nan  # three beams apart now: no occlusion
    assert detect_trees(r).shape[1] == 1


def test_chord_test_rejects_walls():
    r = empty_scan()
    r[150:211] = 10.0 / np.cos(ANGLES[150:211] - math.pi / 2)  # a flat wall 10 m ahead
    assert detect_trees(r).shape[1] == 0


def test_field_of_view_margin_uses_306():
    margin = 5 * math.pi / 306  # 0.0513 rad = 5.87 beams
    for first, expected in ((5, 0), (6, 1)):
        r = empty_scan()
        r[first : first + 3] = 10.0
        assert detect_trees(r).shape[1] == expected, first
    assert 5 * BEAM < margin < 6 * BEAM
    for last, expected in ((355, 0), (354, 1)):
        r = empty_scan()
        r[last - 2 : last + 1] = 10.0
        assert detect_trees(r).shape[1] == expected, last
    # At 0.5 deg, 306 and 360 pick the same beams; a 0.25-deg scan tells them apart:
    # the margin is 11.8 quarter-degree beams (it would be 10 with 5*pi/360).
    ang = np.arange(721) * math.radians(0.25)
    for first, expected in ((11, 0), (12, 1)):
        r = np.full(721, np.nan)
        r[first : first + 3] = 10.0
        assert detect_trees(r, angles_rad=ang).shape[1] == expected, first


def test_minimum_range_is_tested_on_the_first_beam_only():
    r = empty_scan()
    r[100:109] = np.linspace(1.005, 0.995, 9)  # starts beyond 1 m, ends inside it
    assert detect_trees(r).shape[1] == 1
    r[100:109] = np.linspace(0.995, 1.005, 9)  # starts inside 1 m
    assert detect_trees(r).shape[1] == 0


def test_edges_at_different_ranges_are_rejected():
    r = empty_scan()
    r[100:106] = [10.0, 10.1, 10.2, 10.3, 10.4, 10.5]  # a slanted surface: |dR| = 0.5 > d/3
    assert detect_trees(r).shape[1] == 0


def test_max_range_75_m_is_no_return():
    r = empty_scan()
    r[100] = 74.99
    assert detect_trees(r).shape[1] == 1
    r[100] = 75.0
    assert detect_trees(r).shape[1] == 0


def test_params_change_the_rules():
    r = _trunk_scan()
    assert detect_trees(r, params=BaileyParams(max_chord_m=0.3)).shape[1] == 0
    assert detect_trees(r, params=BaileyParams()).shape[1] == 1
    with pytest.raises(ValueError, match="BaileyParams.max_range_m"):
        BaileyParams(max_range_m=math.nan)


# ---- other scans: angles_rad -----------------------------------------------------------------


def test_explicit_original_angles_take_the_original_path():
    r = cast(ANGLES, [trunk_at(10, 1.0, 0.2), trunk_at(7, 2.2, 0.3)])
    np.testing.assert_array_equal(detect_trees(r, angles_rad=ANGLES), detect_trees(r))


def test_other_resolution_and_offset():
    ang = np.arange(181) * math.radians(1.0)  # a 1-degree scanner
    r = cast(ang, [trunk_at(6, 1.2, 0.25)])
    out = detect_trees(r, angles_rad=ang)
    assert out.shape == (3, 1)
    beam = math.radians(1.0)
    assert abs(out[1, 0] - 1.2) <= beam / 2 and abs(out[0, 0] - 6) <= 6 * beam / 2
    # Shifting every angle shifts the bearing and nothing else.
    shifted = detect_trees(r, angles_rad=ang + 0.3)
    np.testing.assert_allclose(shifted, out + [[0], [0.3], [0]], atol=1e-12)


def test_full_circle_scan_finds_a_trunk_on_the_seam_once():
    ang = np.arange(720) * (2 * math.pi / 720)
    for bearing in (0.0, 0.004, 3.0):
        r = cast(ang, [trunk_at(10, bearing, 0.2), trunk_at(8, 2.0, 0.3)])
        out = detect_trees(r, angles_rad=ang)
        assert out.shape == (3, 2), bearing
        expected = sorted([bearing, 2.0])
        np.testing.assert_allclose(out[1], expected, atol=2 * math.pi / 720 / 2)
        assert np.all(np.diff(out[1]) > 0)
    # Beams 0-2 and 357-359 of a 360-beam scan at the edges would fail any field-of-view test:
    # a full scan has none.
    ang = np.arange(360) * math.radians(1.0)
    r = np.full(360, np.nan)
    r[0:3] = 10.0
    assert detect_trees(r, angles_rad=ang).shape[1] == 1


def test_bad_angles_are_rejected():
    r = np.full(5, 10.0)
    with pytest.raises(ValueError, match="angles_rad: expected shape"):
        detect_trees(r, angles_rad=np.arange(4.0))
    with pytest.raises(ValueError, match="strictly increasing"):
        detect_trees(r, angles_rad=np.array([0, 1, 1, 2, 3.0]) * 0.01)
    with pytest.raises(ValueError, match="finite"):
        detect_trees(r, angles_rad=np.array([0, 1, np.nan, 2, 3.0]))
    with pytest.raises(ValueError, match="degrees"):
        detect_trees(r, angles_rad=np.array([0, 90, 180, 270, 360.0]))
    with pytest.raises(ValueError, match="361 beams"):
        detect_trees(r)


@settings(max_examples=200, deadline=None)
@given(
    ranges=arrays(
        np.float64, st.integers(1, 400), elements=st.one_of(st.floats(0, 90), st.just(np.nan))
    ),
    step_deg=st.sampled_from([0.25, 0.5, 1.0]),
    start=st.floats(-3.2, 3.2),
)
def test_numba_kernel_equals_numpy_twin_on_random_scans(ranges, step_deg, start):
    ranges = np.round(ranges, 1)  # clustered values make segments and near-ties common
    ang = start + np.arange(ranges.size) * math.radians(step_deg)
    if ranges.size > 1 and ang[-1] - ang[0] >= 2 * math.pi:
        return
    a = bailey._detect(ranges, ang, bailey._DEFAULT, bailey._kernel_numba)
    b = bailey._detect(ranges, ang, bailey._DEFAULT, bailey._kernel_numpy)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


# ---- the adapter -----------------------------------------------------------------------------


def test_adapter_gives_circles_in_the_laser_frame():
    r = cast(ANGLES, [trunk_at(10, 1.0, 0.2), trunk_at(7, 2.2, 0.3)])
    scan = Scan(r, -math.pi / 2, math.pi / 360, stamp_s=12.5, max_range_m=80.0)
    f = extract_bailey(scan)
    out = detect_trees(r)
    assert f.method == "bailey" and f.stamp_s == 12.5 and f.n_circles == 2
    b_laser = -math.pi / 2 + out[1]
    np.testing.assert_allclose(f.circle_params[:, 0], out[0] * np.cos(b_laser), atol=1e-12)
    np.testing.assert_allclose(f.circle_params[:, 1], out[0] * np.sin(b_laser), atol=1e-12)
    np.testing.assert_allclose(f.circle_params[:, 2], out[2] / 2, atol=1e-12)
    # The truth, moved to the laser frame (beam 0 = the laser's -pi/2): within quantisation.
    for c, (rng, brg) in zip(f.circles, [(10, 1.0), (7, 2.2)]):
        assert c.range_m == pytest.approx(rng, abs=rng * BEAM / 2)
        assert c.bearing_rad == pytest.approx(brg - math.pi / 2, abs=BEAM / 2)
        assert c.first_beam <= round(brg / BEAM) <= c.last_beam
        assert math.isnan(c.rms_residual_m)
    assert f.lines == () and f.edges == ()
    assert f.segment_beams.shape == (2, 2)
    np.testing.assert_array_equal(f.segment_beams, f.circle_beams)
    np.testing.assert_array_equal(f.segment_kind, [KIND_CIRCLE, KIND_CIRCLE])
    assert np.all(np.isnan(f.segment_innov))


def test_adapter_covariance_model():
    r = cast(ANGLES, [trunk_at(20, 1.0, 0.2)])
    f = extract_bailey(Scan(r, -math.pi / 2, math.pi / 360), radius_sigma_m=0.05)
    cov = f.circle_cov[0]
    np.testing.assert_allclose(cov, cov.T, atol=0)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    # Rotate back into beam axes: diag((0.05 + 0.01 r)^2, (r sin 0.5 deg)^2).
    rng, brg = f.circles[0].range_m, f.circles[0].bearing_rad
    u = np.array([math.cos(brg), math.sin(brg)])
    v = np.array([-math.sin(brg), math.cos(brg)])
    assert u @ cov[:2, :2] @ u == pytest.approx((0.05 + 0.01 * rng) ** 2, rel=1e-9)
    assert v @ cov[:2, :2] @ v == pytest.approx((rng * math.sin(math.radians(0.5))) ** 2, rel=1e-9)
    assert u @ cov[:2, :2] @ v == pytest.approx(0, abs=1e-15)
    assert cov[2, 2] == pytest.approx(0.05**2 + (rng * BEAM) ** 2 / 24, rel=1e-12)
    assert cov[0, 2] == cov[1, 2] == 0


def test_adapter_segments_include_rejected_ones():
    r = _trunk_scan()
    r[250:300] = 10.0 / np.cos(ANGLES[250:300] - math.pi / 2)  # a wall: rejected
    f = extract_bailey(Scan(r, -math.pi / 2, math.pi / 360))
    np.testing.assert_array_equal(f.segment_beams, [[178, 182], [250, 299]])
    np.testing.assert_array_equal(f.segment_kind, [KIND_CIRCLE, KIND_CLUTTER])
    assert f.n_circles == 1 and len(f.clutter) == 1


def test_adapter_on_a_simulated_full_circle_scan():
    inc = 2 * math.pi / 720
    ang = -math.pi + np.arange(720) * inc  # two back-to-back sensors, beam 0 behind
    r = cast(ang, [trunk_at(10, math.pi - 0.001, 0.2), trunk_at(8, 0.5, 0.3)])
    f = extract_bailey(Scan(r, -math.pi, inc))
    assert f.n_circles == 2
    bearings = sorted(c.bearing_rad % (2 * math.pi) for c in f.circles)
    np.testing.assert_allclose(bearings, [0.5, math.pi - 0.001], atol=inc / 2)
    seam = [b for b in f.circle_beams if b[0] > b[1] or b[1] >= 720]
    assert len(seam) == 1 and seam[0][1] >= 720  # beams first..last modulo 720


def test_adapter_on_another_resolution_matches_detect_trees():
    inc = math.radians(1.0)
    r = cast(np.arange(181) * inc, [trunk_at(6, 1.2, 0.25)])
    f = extract_bailey(Scan(r, -math.pi / 2, inc))
    out = detect_trees(r, angles_rad=np.arange(181) * inc)
    assert f.n_circles == out.shape[1] == 1
    assert f.circles[0].bearing_rad == pytest.approx(out[1, 0] - math.pi / 2, abs=1e-12)


def test_extract_features_dispatches_to_bailey():
    r = _trunk_scan()
    scan = Scan(r, -math.pi / 2, math.pi / 360)
    a = extract_features(scan, method="bailey", range_sigma_m=0.1)
    b = extract_bailey(scan, range_sigma_m=0.1)
    np.testing.assert_array_equal(a.circle_params, b.circle_params)
    np.testing.assert_array_equal(a.circle_cov, b.circle_cov)


def test_adapter_rejects_bad_arguments():
    scan = Scan(_trunk_scan(), -math.pi / 2, math.pi / 360)
    with pytest.raises(ValueError, match="range_sigma_m"):
        extract_bailey(scan, range_sigma_m=-1.0)
    with pytest.raises(ValueError, match="bearing_sigma_rad"):
        extract_bailey(scan, bearing_sigma_rad=math.nan)
    with pytest.raises(ValueError, match="params"):
        extract_bailey(scan, params={"max_chord_m": 1.0})
    with pytest.raises(ValueError, match="scan"):
        extract_bailey(_trunk_scan())
    with pytest.raises(TypeError):
        extract_bailey(scan, sigma=1.0)


# ---- hostile input ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "ranges",
    [
        np.full(361, np.nan),
        np.full(361, 81.91),  # all "no reflection"
        np.full(361, np.inf),
        np.full(361, -1.0),
        np.zeros(361),
        np.full(361, 1e300),
    ],
    ids=["nan", "no-reflection", "inf", "negative", "zero", "huge"],
)
def test_no_usable_return_gives_no_detection(ranges):
    out = detect_trees(ranges)
    assert out.shape == (3, 0) and out.dtype == np.float64
    f = extract_bailey(Scan(ranges, -math.pi / 2, math.pi / 360))
    assert f.n_circles == 0 and f.circle_params.shape == (0, 3) and f.circle_cov.shape == (0, 3, 3)


def test_empty_and_one_beam():
    assert detect_trees(np.zeros(0), angles_rad=np.zeros(0)).shape == (3, 0)
    assert detect_trees(np.array([5.0]), angles_rad=np.array([0.0])).shape == (3, 0)
    assert extract_bailey(Scan(np.array([5.0]), 0.0, 0.01)).n_circles == 0


def test_zero_range_beams_do_not_crash():
    r = _trunk_scan()
    r[50:60] = 0.0  # zero is below the 1 m start range: kept by the original, never a tree
    assert detect_trees(r).shape[1] == 1


def test_malformed_input_raises_value_error():
    with pytest.raises(ValueError, match="ranges_m: expected shape"):
        detect_trees(np.zeros((2, 361)))
    with pytest.raises(ValueError, match="ranges_m: expected real numbers"):
        detect_trees(np.array(["a"] * 361))
    with pytest.raises(ValueError, match="params"):
        detect_trees(np.zeros(361), params=3)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(
    arrays(
        np.float64,
        361,
        elements=st.one_of(
            st.floats(allow_nan=True, allow_infinity=True), st.floats(0.5, 20.0), st.just(np.nan)
        ),
    )
)
def test_hostile_scans_never_crash(ranges):
    out = detect_trees(ranges)
    assert out.shape[0] == 3 and np.all(np.isfinite(out))
    assert np.all(np.diff(out[1]) > 0)  # increasing bearing
    # The adapter sees the Scan's ranges, where zero, negative and inf are no return too; the
    # original detector keeps zero and negative ranges (they never start a tree).
    scan = Scan(ranges, -math.pi / 2, math.pi / 360)
    f = extract_bailey(scan)
    assert f.n_circles == detect_trees(scan.ranges_m).shape[1]
    assert np.all(np.isfinite(f.circle_params)) and np.all(np.isfinite(f.circle_cov))
    assert np.all(f.circle_params[:, 2] > 0)


def test_the_kernels_read_the_parameters_by_name():
    """`_detect` hands the kernels the `BaileyParams` values as a plain tuple (`_constants`),
    which they name again as a `_Constants`: the same names, in the same order."""
    from dataclasses import fields

    assert bailey._Constants._fields == tuple(f.name for f in fields(BaileyParams))
    p = BaileyParams(max_range_m=70.0, isolation_m=2.5, edge_ratio=0.25)
    named = bailey._Constants(*bailey._constants(p))._asdict()
    assert named == {f.name: getattr(p, f.name) for f in fields(BaileyParams)}

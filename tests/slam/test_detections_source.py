"""`slam.sources.DetectionsSource`: a sequence's precomputed detections as a scan's features
and measurements, without reading the raw scan."""

from __future__ import annotations

import dataclasses

import numpy as np

from features.types import Features
from slam.config import SlamConfig
from slam.sources import DetectionsSource

from .test_run import LANDMARKS, as_detections, drive_sequence, point_features


def test_detections_become_features_with_every_other_field_empty():
    """Each scan's Features: the circles at the detections (centre from range and bearing,
    the radius), no fit covariance, beams or residual, every other field that of
    `Features.empty` (field by field, so a field added to Features is not left out); the
    source reads no raw scan."""
    seq = drive_sequence(1.5, 0.1, n_scans=12)
    feats = point_features(seq, LANDMARKS, np.random.default_rng(7))
    seq = as_detections(seq, feats, "paper")
    source = DetectionsSource(seq, SlamConfig().measurement)
    assert source.needs_scan is False
    empty = Features.empty(0.0, "paper", seq.n_beams)
    n_seen = 0
    for k in range(seq.n_scans):
        f, z, R = source(k, None)
        stored, radius, _ = seq.detections(k)
        n = stored.shape[0]
        n_seen += n
        assert f.n_circles == n == z.shape[0] == R.shape[0]
        centre = stored[:, :1] * np.stack([np.cos(z[:, 1]), np.sin(z[:, 1])], axis=1)
        want = dataclasses.replace(
            empty,
            stamp_s=float(seq.scan_t[k]),
            circle_params=np.column_stack([centre, radius]),
            circle_cov=np.zeros((n, 3, 3)),
            circle_beams=np.zeros((n, 2), np.int64),
            circle_rms_m=np.full(n, np.nan),
        )
        for field in dataclasses.fields(Features):
            a, b = getattr(f, field.name), getattr(want, field.name)
            if isinstance(b, np.ndarray):
                assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), field.name
            else:
                assert a == b, field.name
    assert n_seen > 20

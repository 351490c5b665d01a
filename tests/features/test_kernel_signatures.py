"""The extractors' kernels take one array type whatever the scan: a half circle and a full
circle (whose beams are rotated to start at a seam) reach them alike, so a cold cache compiles
each kernel once (a second signature of `_extract_kernel` and its callees was some 16 s of a
cold warm-up, `experiments.bench.warm`)."""

from __future__ import annotations

import numpy as np

import features.bailey as bailey
import features.extract as extract
from features import METHODS, extract_features
from features.types import Scan


def _scans() -> list[Scan]:
    """A half-circle scan and a full-circle one, each with a trunk and a wall."""
    out = []
    for n, span in ((181, np.pi), (360, 2 * np.pi)):
        angles = -span / 2 + np.arange(n) * (span / n if n == 360 else span / (n - 1))
        ranges = 8.0 / np.maximum(np.abs(np.cos(angles)), 0.2)
        d = 5.0 * np.sin(np.abs(angles))
        on = (d < 0.3) & (np.cos(angles) > 0)
        ranges[on] = 5.0 * np.cos(angles[on]) - np.sqrt(0.09 - d[on] ** 2)
        out.append(Scan(ranges, angle_min_rad=angles[0], angle_increment_rad=angles[1] - angles[0]))
    return out


def test_half_and_full_circle_scans_reach_the_kernels_with_one_signature():
    half, full = _scans()
    assert extract._kernel_beams(full).cyclic and not extract._kernel_beams(half).cyclic
    for scan in (half, full):
        for m in METHODS:
            extract_features(scan, m)
    assert len(extract._extract_kernel.signatures) == 1
    assert len(bailey._circles.signatures) == 1

"""Which object a detected circle belongs to, from per-beam truth labels; false detections.

Labels follow datasets/FORMAT.md: objects 0..L-1 are the landmarks (`truth_landmarks` rows),
other objects have labels >= L, -1 is no return and -2 a mixed return. A circle's beams are the
run `first..last` of its scan (modulo the scan's beam count across a 360 degree seam).
"""

from __future__ import annotations

import numpy as np

from slam import se2

__all__ = ["assign_circles", "dominant_label", "false_detections", "found", "run_labels"]


def run_labels(labels: np.ndarray, first: int, last: int) -> np.ndarray:
    """The labels of beams first..last of a scan whose beams are labelled `labels` (B,)."""
    return labels[np.arange(int(first), int(last) + 1) % labels.shape[0]]


def dominant_label(lab: np.ndarray, returns_only: bool) -> tuple[int, int, int]:
    """(label, its count, the count it is a share of) of the most frequent label in `lab`.

    returns_only: ignore no-return and mixed beams (labels < 0), in the count and the total.
    Ties go to the smaller label. (-1, 0, 0) when nothing is left.
    """
    lab = np.asarray(lab)
    if returns_only:
        lab = lab[lab >= 0]
    if lab.size == 0:
        return -1, 0, 0
    vals, counts = np.unique(lab, return_counts=True)
    i = int(np.argmax(counts))
    return int(vals[i]), int(counts[i]), int(lab.size)


def assign_circles(features, labels: np.ndarray, n_objects: int) -> dict[int, np.ndarray]:
    """object label (0..n_objects-1) -> [x0, y0, r] of the first circle more than half of whose
    beams (no-returns included) hit that object."""
    out = {}
    for (a, b), p in zip(features.circle_beams, features.circle_params):
        k, count, n = dominant_label(run_labels(labels, a, b), returns_only=False)
        if 0 <= k < n_objects and 2 * count > n and k not in out:
            out[k] = p
    return out


def found(features, labels: np.ndarray, label: int) -> bool:
    """Whether some circle has more than half of its beams on object `label`."""
    for a, b in features.circle_beams:
        k, count, n = dominant_label(run_labels(labels, a, b), returns_only=False)
        if k == label and 2 * count > n:
            return True
    return False


def false_detections(
    features,
    labels: np.ndarray,
    laser_world_pose: np.ndarray,
    truth_landmarks: np.ndarray,
    false_match_m: float = 0.5,
) -> tuple[int, int]:
    """(detected, false) circles of one scan.

    A circle is false when its beams with a return do not mostly (more than half) hit one
    landmark, or when its centre, placed in the world with the laser's true pose, lies more than
    `false_match_m` from that landmark's centre.
    """
    n = int(features.n_circles)
    if n == 0:
        return 0, 0
    L = truth_landmarks.shape[0]
    false = 0
    for (a, b), p in zip(features.circle_beams, features.circle_params):
        j, count, n_ret = dominant_label(run_labels(labels, a, b), returns_only=True)
        if n_ret == 0 or j >= L or 2 * count <= n_ret:
            false += 1
            continue
        w = se2.transform_points(laser_world_pose, p[:2])
        if np.hypot(*(w - truth_landmarks[j, :2])) > false_match_m:
            false += 1
    return n, false

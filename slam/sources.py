"""Where a run's measurements come from: one source per run, chosen once from the configuration
(`make_source`), each giving scan k's circles as range-bearing measurements through the one
measurement model of the configuration (`slam.measurement.MeasurementModel.measure`).

- `ExtractorSource`: `features.extract_features` on the raw scans, with the configuration's
  extractor parameters (`SlamConfig.features`);
- `DetectionsSource`: the sequence's precomputed detections (`Sequence.detections`);
- `GivenSource`: a list of precomputed `Features` (a features file, an experiment's extraction),
  or a callable (k, scan) -> Features.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from features.types import Features
from slam.config import OWN_COVARIANCE, FeaturesConfig, MeasurementConfig, SlamConfig
from slam.errors import SlamError
from slam.measurement import MeasurementModel
from slam.sequence import Sequence
from slam.validators import readonly

__all__ = ["DetectionsSource", "ExtractorSource", "GivenSource", "Measurements", "make_source"]


@dataclass(frozen=True, eq=False)
class Measurements:
    """Scan k's circles as measurements of their centres, laser frame.

    scan: the `features.Scan` (None without raw ranges, and from a source that does not read
    it, `needs_scan` False: `slam.visual.show_scan` then builds it when the sequence has
    ranges); features: its `Features`
    (for the log and the visualiser); z (m, 2) [range m, bearing rad] and R (m, 2, 2) from the
    source's measurement model; status (m,) int64 as measured: NEW_TENTATIVE, or OUT_OF_RANGE
    beyond the usable range (`slam.log` codes; the scan's final status is
    `slam.loop.ScanResult`)."""

    k: int
    scan: object
    features: Features
    z: np.ndarray
    R: np.ndarray
    status: np.ndarray

    def __post_init__(self) -> None:
        # the map managers' kernels index z, R and status together, unchecked
        m = np.shape(self.z)[0] if np.ndim(self.z) == 2 else -1
        if (
            np.shape(self.z) != (m, 2)
            or np.shape(self.R) != (m, 2, 2)
            or np.shape(self.status) != (m,)
        ):
            raise SlamError(
                "Measurements: needs z (m, 2), R (m, 2, 2) and status (m,) of one m, got "
                f"{np.shape(self.z)}, {np.shape(self.R)} and {np.shape(self.status)}"
            )

    @property
    def radius_m(self) -> np.ndarray:
        """(m,) the circles' radii (NaN where the source has none)."""
        return np.asarray(self.features.circle_params, float).reshape(-1, 3)[:, 2]


class ExtractorSource:
    """Circles extracted from the raw scans by `method` with the configured parameters."""

    def __init__(
        self, seq: Sequence, features: FeaturesConfig, measurement: MeasurementConfig
    ) -> None:
        self.method = features.method
        if not seq.has_ranges:
            raise SlamError(
                f"features: {self.method!r} extracts from raw scans, and this sequence has none; "
                "use the method 'detections'"
            )
        self.params, self.options = features.extractor_args()
        self.model = measurement.model_for(self.method)
        self.count = None  # not precomputed

    needs_scan = True  # the loop passes scan k as a `features.Scan`

    def __call__(self, k: int, scan) -> tuple[Features, np.ndarray, np.ndarray]:
        from features import extract_features

        f = extract_features(scan, self.method, self.params, **self.options)
        return (f, *self.model.from_features(f))


class DetectionsSource:
    """The sequence's precomputed detections: z as stored (less the known range bias of their
    method), R their covariance plus the fit floor or the constant model of their method; the
    Features (circles at the detections) are for the log and the visualiser.

    The measurement model is elementwise, so it is applied once to every detection of the
    sequence (the same numbers as scan by scan) and a scan takes its rows: a scan then costs a
    few slices, not the dozen small array operations of building them."""

    def __init__(self, seq: Sequence, measurement: MeasurementConfig) -> None:
        if not seq.has_detections:
            raise SlamError(
                "features: 'detections' needs a sequence with precomputed detections (det_scan, "
                f"...); {seq.name or 'this sequence'!r} has none"
            )
        self.seq = seq
        self.method = seq.det_method
        self.model: MeasurementModel = measurement.model_for(
            seq.det_method, seq.det_cov is not None
        )
        if self.model.kind == "fit" and seq.det_cov is None:
            raise SlamError("measurement.noise: 'fit' needs det_cov in the sequence's detections")
        # the arrays of no lines, edges or segments, shared by every scan's Features (read-only)
        self._empty = Features.empty(0.0, seq.det_method, seq.n_beams)
        self.count = None
        self._bounds = np.searchsorted(seq.det_scan, np.arange(seq.n_scans + 1))
        stored = np.stack([seq.det_range, seq.det_bearing], axis=1)
        self._z, self._R = self.model.measure(stored, seq.det_cov)
        c, s = np.cos(self._z[:, 1]), np.sin(self._z[:, 1])
        n = stored.shape[0]
        self._circles = readonly(
            np.column_stack([stored[:, 0] * c, stored[:, 0] * s, seq.det_radius])
        )
        self._no_cov = readonly(np.zeros((n, 3, 3)))
        self._no_beams = readonly(np.zeros((n, 2), np.int64))
        self._no_rms = readonly(np.full(n, np.nan))

    needs_scan = False  # the detections are read from the sequence: the loop builds no Scan

    def __call__(self, k: int, scan) -> tuple[Features, np.ndarray, np.ndarray]:
        a, b = int(self._bounds[k]), int(self._bounds[k + 1])
        e = self._empty  # written out, not `dataclasses.replace` (its field loop, every scan)
        f = Features(
            stamp_s=float(self.seq.scan_t[k]),
            circle_params=self._circles[a:b],
            circle_cov=self._no_cov[a:b],
            circle_beams=self._no_beams[a:b],
            circle_rms_m=self._no_rms[a:b],
            line_params=e.line_params,
            line_cov=e.line_cov,
            line_endpoints=e.line_endpoints,
            line_beams=e.line_beams,
            line_rms_m=e.line_rms_m,
            edge_xy=e.edge_xy,
            edge_cov=e.edge_cov,
            edge_beam=e.edge_beam,
            segment_beams=e.segment_beams,
            segment_kind=e.segment_kind,
            segment_innov=e.segment_innov,
            method=e.method,
            n_beams=e.n_beams,
        )
        return f, self._z[a:b].copy(), self._R[a:b].copy()


class GivenSource:
    """Features the caller made: a list of N `Features` (one per scan) or a callable (k, scan)
    -> Features. A list whose circles' covariances are all zero carries none of its own
    (measurement noise "auto" then takes the constant model, not the fit floors alone)."""

    def __init__(self, given, measurement: MeasurementConfig) -> None:
        if callable(given):
            self._get: Callable = given
            self.method = getattr(given, "method", "custom")
            self.count, has_cov = None, self.method in OWN_COVARIANCE
        elif isinstance(given, (list, tuple)):
            feats = list(given)
            bad = [k for k, f in enumerate(feats) if not isinstance(f, Features)]
            if bad:
                raise SlamError(
                    f"features: item {bad[0]} is {type(feats[bad[0]]).__name__}, expected a "
                    "features.Features"
                )
            self._get = lambda k, scan: feats[k]
            self.method = feats[0].method if feats else "custom"
            self.count = len(feats)
            own = self.method in OWN_COVARIANCE
            has_cov = own and any(np.any(np.asarray(f.circle_cov)) for f in feats if f.n_circles)
        else:
            raise SlamError(
                "features: expected a method name, a callable (k, scan) -> Features or a list "
                f"of Features, got {type(given).__name__}"
            )
        self.model = measurement.model_for(self.method, has_cov)

    needs_scan = True  # a callable may read it

    def __call__(self, k: int, scan) -> tuple[Features, np.ndarray, np.ndarray]:
        f = self._get(k, scan)
        if not isinstance(f, Features):
            raise SlamError(
                f"features: scan {k} gave {type(f).__name__}, expected a features.Features"
            )
        return (f, *self.model.from_features(f))


def make_source(seq: Sequence, cfg: SlamConfig, given=None):
    """The run's source: `given` features (a list or a callable) when there are some, else the
    configuration's method ("detections" or an extractor)."""
    if given is not None:
        return GivenSource(given, cfg.measurement)
    if cfg.features.method == "detections":
        return DetectionsSource(seq, cfg.measurement)
    return ExtractorSource(seq, cfg.features, cfg.measurement)

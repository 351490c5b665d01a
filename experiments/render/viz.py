"""Rerun inspection: our dataclasses as rerun entities on the timelines `scan` (index) and
`time` (the scan's time, s, when known).

The only module that imports rerun. Entities (laser frame unless a pose is given):
  world/scan                 scan points (grey)
  world/features/segments    one strip per segment, coloured by kind (line blue, circle green,
                             clutter orange)
  world/features/circles     fitted circles (outline), labelled with radius
  world/features/lines       fitted lines (projected endpoints)
  world/features/edges       occluding edges (red crosses)
  world/truth/...            simulated truth when known
SLAM runs (slam.run's visualiser interface, world frame):
  world/vehicle              pose arrow, 95% position ellipse (3-sigma heading in the label)
  world/vehicle/path         estimated path so far
  world/landmarks            map landmarks: centres, ids, 95% ellipses
  world/tentative            tentative features (not yet in the map)
  world/associations         lines from each associated measurement to its landmark
  world/truth/vehicle        true pose and path (simulated runs)
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import numpy as np
import rerun as rr

from experiments.errors import DataError
from experiments.io.writers import check_output_file
from experiments.render.shapes import circle_polyline, ellipse_polyline
from features.types import Features, Scan
from slam import se2

__all__ = ["NullRecorder", "Recorder", "open_recording"]

KIND_COLORS = np.array([[255, 150, 40], [60, 120, 255], [40, 200, 90]], dtype=np.uint8)
METHOD_COLORS = {
    "paper": [40, 200, 90],
    "geometric": [220, 60, 220],
    "bailey": [255, 200, 0],
    "kasa": [0, 200, 220],
    "taubin": [150, 150, 255],
    "truth": [255, 255, 255],
}


def _transform(xy: np.ndarray, pose: np.ndarray | None) -> np.ndarray:
    if pose is None or len(xy) == 0:
        return xy
    return se2.transform_points(pose, xy)


class NullRecorder:
    """Does nothing: the default visualiser, so algorithms and loops never need rerun."""

    def set_scan(self, k: int, stamp_s: float | None = None) -> None: ...
    def log_scan(self, scan: Scan, pose=None, path: str = "world/scan") -> None: ...
    def log_features(self, scan, features, pose=None, path="world/features") -> None: ...
    def log_circles(self, path, circles_xyr, pose=None, method="truth", labels=None) -> None: ...
    def log_vehicle(self, pose, cov) -> None: ...
    def log_landmarks(self, xy, cov, ids) -> None: ...
    def log_tentatives(self, xy) -> None: ...
    def log_associations(self, from_xy, to_xy) -> None: ...
    def log_truth(self, pose) -> None: ...
    def close(self) -> None: ...
    def abort(self) -> None: ...

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Closed (the recording put in place) when the block succeeds; aborted (nothing left
        behind) when it raises or is interrupted."""
        if exc_type is None:
            self.close()
        else:
            self.abort()


class Recorder(NullRecorder):
    """Writes a `.rrd` recording (open it with `rerun FILE.rrd`).

    The recording goes to a temporary file beside `path` (`.NAME.XXXX.rrd.tmp`) and is renamed
    to `path` by `close()`: an interrupted run never leaves a truncated recording at `path`.
    `abort()` (or leaving a `with` block by an exception) deletes the temporary file."""

    def __init__(self, path: Path | str, app_id: str = "trunkslam", decimate: int = 1):
        """decimate: log the scene of every this-many scans only (paths still grow every scan);
        a whole Victoria Park run at 1 would be gigabytes."""
        self.path = Path(path)
        self.decimate = max(int(decimate), 1)
        self._k = 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        check_output_file(self.path, "recording")
        try:
            fd, tmp = tempfile.mkstemp(
                dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".rrd.tmp"
            )
        except OSError as exc:
            raise DataError(f"recording {self.path}: cannot be written ({exc.strerror})") from None
        os.close(fd)
        self._tmp = Path(tmp)
        try:
            self.rec = rr.RecordingStream(app_id)
            self.rec.save(str(self._tmp))
            self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Y_UP, static=True)
        except RuntimeError as exc:  # rerun's error when it cannot create the file
            self._tmp.unlink(missing_ok=True)
            raise DataError(f"recording {self.path}: cannot be written ({exc})") from None
        except BaseException:  # interrupted while opening: leave nothing behind
            self._tmp.unlink(missing_ok=True)
            raise

    def _skip(self) -> bool:
        return self._k % self.decimate != 0

    def set_scan(self, k: int, stamp_s: float | None = None) -> None:
        """Timeline `scan` = k; with the scan's time, also timeline `time` (seconds)."""
        self._k = int(k)
        self.rec.set_time("scan", sequence=int(k))
        if stamp_s is not None:
            self.rec.set_time("time", duration=float(stamp_s))

    def log_scan(self, scan: Scan, pose=None, path: str = "world/scan") -> None:
        if self._skip():
            return
        pts = scan.points_xy[scan.valid]
        self.rec.log(path, rr.Points2D(_transform(pts, pose), radii=0.03, colors=[180, 180, 180]))

    def log_features(self, scan: Scan, features: Features, pose=None, path="world/features"):
        if self._skip():
            return
        pts = scan.points_xy
        strips, colors = [], []
        for (a, b), k in zip(features.segment_beams, features.segment_kind):
            strips.append(_transform(pts[features.beams(a, b)], pose))
            colors.append(KIND_COLORS[int(k)])
        self.rec.log(f"{path}/segments", rr.LineStrips2D(strips, colors=colors, radii=0.02))
        self.log_circles(f"{path}/circles", features.circle_params, pose, features.method)
        lines = [_transform(e, pose) for e in features.line_endpoints]
        self.rec.log(f"{path}/lines", rr.LineStrips2D(lines, colors=[60, 120, 255], radii=0.04))
        self.rec.log(
            f"{path}/edges",
            rr.Points2D(_transform(features.edge_xy, pose), radii=0.12, colors=[255, 40, 40]),
        )

    def log_circles(self, path, circles_xyr, pose=None, method="truth", labels=None):
        circles_xyr = np.asarray(circles_xyr, float).reshape(-1, 3)
        strips = [_transform(circle_polyline(*c), pose) for c in circles_xyr]
        if labels is None:
            labels = [f"r={c[2]:.3f} m" for c in circles_xyr]
        self.rec.log(
            path,
            rr.LineStrips2D(
                strips,
                colors=METHOD_COLORS.get(method, [255, 255, 255]),
                labels=labels,
                radii=0.015,
            ),
        )

    # ---- SLAM (the visualiser interface of slam.run; world frame) -------------------------------

    def log_vehicle(self, pose, cov) -> None:
        """Estimated pose (arrow), 95% position ellipse and the path so far."""
        pose = np.asarray(pose, float)
        cov = np.asarray(cov, float)
        path = self.__dict__.setdefault("_est_path", [])
        path.append(pose[:2].copy())
        if self._skip():
            return
        head = 1.0 * np.array([np.cos(pose[2]), np.sin(pose[2])])
        sig_th = float(np.sqrt(max(cov[2, 2], 0.0)))
        self.rec.log(
            "world/vehicle",
            rr.Arrows2D(
                origins=[pose[:2]],
                vectors=[head],
                colors=[[255, 80, 80]],
                labels=[f"3 sigma heading +-{np.degrees(3 * sig_th):.2f} deg"],
            ),
        )
        self.rec.log(
            "world/vehicle/ellipse",
            rr.LineStrips2D(
                [ellipse_polyline(pose[:2], cov[:2, :2])], colors=[[255, 80, 80]], radii=0.01
            ),
        )
        self.rec.log(
            "world/vehicle/path",
            rr.LineStrips2D([np.array(path)], colors=[[255, 80, 80]], radii=0.02),
        )

    def log_landmarks(self, xy, cov, ids) -> None:
        if self._skip():
            return
        xy = np.asarray(xy, float).reshape(-1, 2)
        cov = np.asarray(cov, float).reshape(-1, 2, 2)
        labels = [f"L{int(i)}" for i in ids]
        self.rec.log(
            "world/landmarks", rr.Points2D(xy, radii=0.08, colors=[[40, 200, 90]], labels=labels)
        )
        self.rec.log(
            "world/landmarks/ellipses",
            rr.LineStrips2D(
                [ellipse_polyline(c, P) for c, P in zip(xy, cov)],
                colors=[[40, 200, 90]],
                radii=0.01,
            ),
        )

    def log_tentatives(self, xy) -> None:
        if self._skip():
            return
        xy = np.asarray(xy, float).reshape(-1, 2)
        self.rec.log("world/tentative", rr.Points2D(xy, radii=0.06, colors=[[255, 200, 0]]))

    def log_associations(self, from_xy, to_xy) -> None:
        if self._skip():
            return
        a = np.asarray(from_xy, float).reshape(-1, 2)
        b = np.asarray(to_xy, float).reshape(-1, 2)
        self.rec.log(
            "world/associations",
            rr.LineStrips2D(
                [np.stack([p, q]) for p, q in zip(a, b)], colors=[[0, 200, 255]], radii=0.02
            ),
        )

    def log_truth(self, pose) -> None:
        """True pose (arrow) and path so far."""
        pose = np.asarray(pose, float)
        path = self.__dict__.setdefault("_truth_path", [])
        path.append(pose[:2].copy())
        if self._skip():
            return
        self.rec.log(
            "world/truth/vehicle",
            rr.Arrows2D(
                origins=[pose[:2]],
                vectors=[[np.cos(pose[2]), np.sin(pose[2])]],
                colors=[[255, 255, 255]],
            ),
        )
        self.rec.log(
            "world/truth/vehicle/path",
            rr.LineStrips2D([np.array(path)], colors=[[255, 255, 255]], radii=0.015),
        )

    def close(self) -> None:
        """Finish the recording and put it at `path` (atomically: a rename)."""
        if self._tmp is None:
            return
        try:
            self.rec.flush()
            self.rec.disconnect()  # closes the file sink
            os.chmod(self._tmp, 0o644)
            os.replace(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise
        self._tmp = None

    def abort(self) -> None:
        """Drop the recording: the temporary file is deleted, `path` is left as it was."""
        if self._tmp is None:
            return
        with contextlib.suppress(Exception):
            self.rec.disconnect()
        self._tmp.unlink(missing_ok=True)
        self._tmp = None


def open_recording(path: Path | str | None, decimate: int = 1) -> NullRecorder:
    """A Recorder writing to `path` (see `Recorder` for decimate), or a NullRecorder when path
    is None."""
    return NullRecorder() if path is None else Recorder(path, decimate=decimate)

"""The Victoria Park dataset (ACFR, Guivant & Nebot) as a `Sequence`, plus the reference detections.

Conventions (see `../shared/datasets/victoria_park/README.md`):
- the original clocks are milliseconds (the reference file's TLsr is already seconds);
  everything here is seconds;
- raw laser words keep the range in cm in their low 13 bits (mask 8191); ranges >= 80 m
  (8000 cm) mean "no reflection";
- beam i (0..360) of the SICK points at i*pi/360 from the vehicle's right, i.e. at
  -pi/2 + i*pi/360 in the laser frame (x forward like the vehicle);
- the laser (and the GPS antenna) sits at (L + a, b) = (3.78, 0.50) m in the vehicle frame
  (rear-axle centre, x forward, y left); wheelbase L = 2.83 m; the speed encoder is on the
  rear-left wheel, H = 0.76 m left of the centre line.
Only the first 2000 raw scans exist (`partial_raw_scans_ss2002/sick.mat`); their times are
`TLsr(1:2000)` of `reference_detections/VictoriaParkSinSincronizar.mat`.
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError, DataError, MissingDataError
from experiments.io.paths import how_to_get, victoria_park_dir
from slam import Sequence

__all__ = [
    "VP_LASER_POSE",
    "VP_N_SCANS",
    "VP_VEHICLE",
    "VP_MAX_RANGE_M",
    "VP_N_RAW_SCANS",
    "GTSAM_GRAPH",
    "VP_FILES",
    "VP_SHA256",
    "readme_sha256",
    "verify_file",
    "gtsam_graph",
    "load_victoria_park",
    "load_reference_detections",
    "load_raw_sick_ranges",
    "load_raw_sick_words",
    "load_ss2002_reference",
]

VP_LASER_POSE = (3.78, 0.50, 0.0)  # (L + a, b, 0) in the vehicle frame, m, m, rad
VP_VEHICLE = {"model": "ackermann", "wheelbase_m": 2.83, "encoder_offset_m": 0.76}
VP_MAX_RANGE_M = 80.0  # 8000 cm: "no reflection" at or beyond
VP_N_RAW_SCANS = 2000
VP_N_SCANS = 7249
VP_ANGLE_MIN_RAD = -math.pi / 2
VP_ANGLE_INCREMENT_RAD = math.pi / 360
RANGE_MASK = 8191  # low 13 bits: range in cm

VP_FILES = {
    "odometry": "aa3_dr.mat",
    "gps": "aa3_gpsx.mat",
    "sick": "partial_raw_scans_ss2002/sick.mat",
    "reference": "reference_detections/VictoriaParkSinSincronizar.mat",
}
# the 2002 SLAM summer school's solution over scans 1-2000 (a reference, not ground truth)
SS2002_FILES = {
    "vehicle": "partial_raw_scans_ss2002/vehicle.mat",
    "features": "partial_raw_scans_ss2002/features.mat",
}


# sha256 of the published files (the data folder's README.md lists the same sums, with sources)
VP_SHA256 = {
    "aa3_dr.mat": "6ce2c4f757023b7d275cc14f24ff2ffcca21ea68cfa360bc854e620a706eb358",
    "aa3_gpsx.mat": "521fc4c6e0ea3851ffb463c3d9c0578044e9178c4fb87f37c703bb587f38c755",
    "partial_raw_scans_ss2002/sick.mat": (
        "9853c3e000378d3963d31230ba5985a14487058409d1324743bf23149c4874f9"
    ),
    "partial_raw_scans_ss2002/vehicle.mat": (
        "31ed0abc45dbb1ce3bd9147a7c150e65f175fb7ec81864688aa6feeac81c520c"
    ),
    "partial_raw_scans_ss2002/features.mat": (
        "2b6a85d4ada482df2fdfd119258d4040e14ae2706d3455befda8bbd6247d8c14"
    ),
    "reference_detections/VictoriaParkSinSincronizar.mat": (
        "8e5212b3028d40f64dcf7b43f68f89e67ea4b0c0b3ec01835997381fe9d96997"
    ),
    "gtsam/victoria_park.txt": "10596bac625acfe009080748b0ec9993fc9925a93370878c20288a22eeee5253",
}
GTSAM_GRAPH = "gtsam/victoria_park.txt"
_SHA_ROW = re.compile(r"^\|\s*`([^`]+)`\s*\|[^|]*\|\s*`([0-9a-f]{64})`", re.MULTILINE)
_verified: dict[tuple[str, int, int], str] = {}  # (path, size, mtime_ns) -> sha256 seen


def readme_sha256(root: Path) -> dict[str, str]:
    """The sha256 sums the data folder's README.md lists ({relative path: sum}); {} without
    a README."""
    try:
        text = (root / "README.md").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return {}
    return dict(_SHA_ROW.findall(text))


def verify_file(root: Path, rel: str) -> Path:
    """`root / rel`, after checking its sha256 against the sum the data README lists (or, with
    no README or no row for it, `VP_SHA256`): `DataError` naming the file that differs. The
    sum of a file already checked (same size and modification time) is not recomputed."""
    path = root / rel
    expected = readme_sha256(root).get(rel) or VP_SHA256.get(rel)
    if expected is None:
        return path
    try:
        st = path.stat()
    except FileNotFoundError:
        raise MissingDataError(f"Victoria Park file missing: {path}; {how_to_get()}") from None
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    got = _verified.get(key)
    if got is None:
        h = hashlib.sha256()
        try:
            with open(path, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
        except OSError as exc:
            raise DataError(f"{path}: cannot be read ({exc})") from None
        got = _verified[key] = h.hexdigest()
    if got != expected:
        raise DataError(
            f"{path}: sha256 {got} differs from the published file's {expected}: the file is "
            f"corrupt or another version; {how_to_get()}"
        )
    return path


def gtsam_graph(root: Path | str | None = None) -> Path:
    """GTSAM's preprocessed Victoria Park graph (`gtsam/victoria_park.txt`), its sha256 checked;
    `MissingDataError` when absent, `DataError` when it differs."""
    return verify_file(_root(root), GTSAM_GRAPH)


def _root(root: Path | str | None) -> Path:
    return victoria_park_dir() if root is None else Path(root)


def load_mat(root: Path, key: str, variables: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Load `VP_FILES[key]` under `root` and check that it has `variables`."""
    from scipy.io import loadmat  # heavy-ish import, only when reading data

    path = root / VP_FILES[key]
    if not path.is_file():
        raise MissingDataError(f"Victoria Park file missing: {path}; {how_to_get()}")
    verify_file(root, VP_FILES[key])
    try:
        mat = loadmat(path)
    except Exception as exc:  # scipy raises assorted errors on corrupt files
        raise DataError(
            f"{path}: cannot be read as a MATLAB file ({exc}); {how_to_get()}"
        ) from None
    missing = [v for v in variables if v not in mat]
    if missing:
        raise DataError(f"{path}: missing variable(s) {missing}; {how_to_get()}")
    return mat


def _column(path_key: str, mat: dict, name: str, length: int | None = None) -> np.ndarray:
    a = np.asarray(mat[name])
    if a.ndim != 2 or 1 not in a.shape:
        raise DataError(f"{VP_FILES[path_key]}: {name} should be a vector, got shape {a.shape}")
    a = a.ravel()
    if length is not None and a.size != length:
        raise DataError(
            f"{VP_FILES[path_key]}: {name} has {a.size} entries, expected {length} like the others"
        )
    return a


def load_raw_sick_words(root: Path | str | None = None) -> np.ndarray:
    """The raw SICK words of scans 1..2000: (2000, 361) uint16 (range cm in the low 13 bits)."""
    root = _root(root)
    mat = load_mat(root, "sick", ("sick",))
    words = np.asarray(mat["sick"])
    if words.shape != (VP_N_RAW_SCANS, 361) or words.dtype.kind not in "iu":
        raise DataError(
            f"{root / VP_FILES['sick']}: sick should be ({VP_N_RAW_SCANS}, 361) integers, "
            f"got {words.shape} {words.dtype}"
        )
    return words.astype(np.uint16)


def load_raw_sick_ranges(
    root: Path | str | None = None, *, no_return_as_nan: bool = True
) -> np.ndarray:
    """Ranges of raw scans 1..2000: (2000, 361) float64 metres = (word & 8191) / 100.

    no_return_as_nan: readings >= 80 m ("no reflection") become NaN; with False they stay as
        the masked values (up to 81.91 m), exactly the original detector's input. Either feeds
        `features.bailey.detect_trees` identically, since it ignores everything >= 75 m.
    """
    ranges = (load_raw_sick_words(root) & RANGE_MASK).astype(np.float64) / 100.0
    if no_return_as_nan:
        ranges[ranges >= VP_MAX_RANGE_M] = np.nan
    return ranges


def load_reference_detections(
    root: Path | str | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The original detector's output on all 7249 scans, and the scan times.

    Returns t_s (7249,) float64 seconds (TLsr) and a list of 7249 (3, n) float64 arrays
    [range (m); bearing (rad, 0..pi from the vehicle's right); diameter (m)], (3, 0) when empty.
    """
    root = _root(root)
    mat = load_mat(root, "reference", ("TLsr", "zt"))
    t_s = _column("reference", mat, "TLsr").astype(np.float64)
    zt = np.asarray(mat["zt"]).ravel()
    if zt.size != t_s.size:
        raise DataError(
            f"{root / VP_FILES['reference']}: zt has {zt.size} cells but TLsr {t_s.size} times"
        )
    dets: list[np.ndarray] = []
    for k, cell in enumerate(zt):
        a = np.asarray(cell, dtype=np.float64)
        if a.size == 0:
            a = np.zeros((3, 0))
        elif a.ndim != 2 or a.shape[0] != 3:
            raise DataError(
                f"{root / VP_FILES['reference']}: zt{{{k + 1}}} should be 3 x n, got {a.shape}"
            )
        dets.append(a)
    return t_s, dets


def load_victoria_park(
    root: Path | str | None = None,
    n_scans: int | None = None,
    *,
    full: bool = False,
    progress: Callable[[str, int, int], None] | None = None,
) -> Sequence:
    """The Victoria Park run as a `Sequence`, with odometry, GPS and the published detections.

    root: the `victoria_park` folder (default: `experiments.io.paths.victoria_park_dir()`).
    full: False (default): the 2000 scans that have raw laser data (scans 1-2000, 21.8-448.9 s),
        with the published detections beside them; True: all 7249 scans (1548 s of driving) with
        the published detections only (`scan_n_beams` 361, no raw ranges).
    n_scans: keep the first n_scans scans (1..2000, or 1..7249 with full). Odometry (61945 rows,
        the whole 26 min) and GPS (4466 fixes) are always complete.
    progress: callback(description, files read, files to read) after each file.
    Scans: ranges (word & 8191) / 100 m, >= 80 m -> NaN, scan_max_range 80 m; angle_min -pi/2,
    increment pi/360 (laser frame, x forward). gps_xy = [Lo_m, La_m] (x east, y north, m);
    gps_pose = laser position (the antenna sits at the laser). Detections (det_method
    "bailey", the original detector's output): det_range = its range to the trunk centre,
    det_bearing = its bearing - pi/2 (laser frame), det_radius = its diameter / 2.
    """
    limit = VP_N_SCANS if full else VP_N_RAW_SCANS
    if n_scans is not None and (
        isinstance(n_scans, bool)
        or not isinstance(n_scans, (int, np.integer))
        or not 1 <= n_scans <= limit
    ):
        raise ConfigError(f"n_scans: must be an integer in 1..{limit}, got {n_scans!r}")
    root = _root(root)
    n = limit if n_scans is None else int(n_scans)
    n_files = 3 if full else 4

    def step(done: int, total: int) -> None:
        if progress is not None:
            progress("reading Victoria Park", done, total)

    step(0, n_files)
    t_all, dets = load_reference_detections(root)
    step(1, n_files)
    if t_all.size < limit:
        raise DataError(f"{root / VP_FILES['reference']}: TLsr has only {t_all.size} times")
    ranges = None
    if not full:
        ranges = load_raw_sick_ranges(root)[:n]
        step(2, n_files)
    detections = _detections(dets[:n])
    odometry = _odometry(root)
    step(n_files - 1, n_files)
    gps = _gps(root)
    step(n_files, n_files)
    return Sequence(
        scan_t=t_all[:n],
        scan_ranges=ranges,
        scan_n_beams=361,
        scan_angle_min=VP_ANGLE_MIN_RAD,
        scan_angle_increment=VP_ANGLE_INCREMENT_RAD,
        laser_pose=np.array(VP_LASER_POSE),
        scan_max_range=VP_MAX_RANGE_M,
        **detections,
        **odometry,
        vehicle=dict(VP_VEHICLE),
        **gps,
        name="victoria_park (full run, published detections)" if full else "victoria_park",
    )


def _detections(dets: list[np.ndarray]) -> dict[str, np.ndarray | str]:
    """The published detections of the scans (one 3 x n array each: range, bearing from the
    vehicle's right, diameter) as the `Sequence` fields det_*, in the laser frame."""
    k = np.concatenate([np.full(d.shape[1], i) for i, d in enumerate(dets)]).astype(np.int64)
    d = np.concatenate(dets, axis=1)
    return {
        "det_scan": k,
        "det_range": d[0],
        "det_bearing": d[1] - math.pi / 2,
        "det_radius": d[2] / 2,
        "det_method": "bailey",
    }


def _odometry(root: Path) -> dict[str, np.ndarray]:
    """The odometry file as the `Sequence` fields odo_*: times (s), speed (m/s), steering."""
    dr = load_mat(root, "odometry", ("time", "speed", "steering"))
    odo_ms = _column("odometry", dr, "time")
    return {
        "odo_t": odo_ms.astype(np.float64) / 1000.0,
        "odo_speed": _column("odometry", dr, "speed", odo_ms.size),
        "odo_steer": _column("odometry", dr, "steering", odo_ms.size),
    }


def _gps(root: Path) -> dict[str, np.ndarray]:
    """The GPS file as the `Sequence` fields gps_*: times (s), fixes [east, north] (m), and the
    antenna's pose in the vehicle frame (at the laser)."""
    gps = load_mat(root, "gps", ("timeGps", "La_m", "Lo_m"))
    gps_ms = _column("gps", gps, "timeGps")
    lo = _column("gps", gps, "Lo_m", gps_ms.size)
    la = _column("gps", gps, "La_m", gps_ms.size)
    return {
        "gps_t": gps_ms.astype(np.float64) / 1000.0,
        "gps_xy": np.stack([lo, la], axis=1),
        "gps_pose": np.array(VP_LASER_POSE),
    }


def load_ss2002_reference(root: Path | str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The 2002 SLAM summer school's solution over scans 1-2000 (Zaragoza, J. Neira and J.
    Tardos): its vehicle poses (2000, 3) [x, y, phi] (`vehicle.ground`, relative to the first
    scan's pose) and its map of 145 trees (145, 3) [x, y, r] in the same frame. A SLAM result,
    not surveyed truth; compare a map with it after aligning the two paths."""
    import scipy.io

    root = _root(root)
    out = []
    for key, var in (("vehicle", "vehicle"), ("features", "features")):
        path = root / SS2002_FILES[key]
        if path.is_file():
            verify_file(root, SS2002_FILES[key])
        try:
            mat = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
        except FileNotFoundError:
            raise MissingDataError(f"{path}: not found; {how_to_get()}") from None
        except Exception as exc:  # scipy raises many types for a corrupt file
            raise DataError(f"{path}: cannot be read as a MATLAB file ({exc})") from None
        if var not in mat:
            raise DataError(f"{path}: missing variable {var!r}")
        out.append(mat[var])
    vehicle, feats = out
    try:
        ground = np.array([np.asarray(g.x, float).reshape(3) for g in vehicle.ground])
        xy = np.asarray(feats.x, float).reshape(-1, 2)
        r = np.asarray(feats.radius, float).reshape(-1)
    except (AttributeError, ValueError, TypeError) as exc:
        raise DataError(f"{root / SS2002_FILES['vehicle']}: unexpected layout ({exc})") from None
    if ground.shape != (VP_N_RAW_SCANS, 3) or r.shape[0] != xy.shape[0]:
        raise DataError(f"{root}: the SS2002 reference has an unexpected size {ground.shape}")
    return ground, np.column_stack([xy, r])

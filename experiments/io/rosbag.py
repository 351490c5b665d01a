"""A robot's ROS bag as a `Sequence`: ROS 1 `.bag`, ROS 2 bags (sqlite3 `.db3` or MCAP), or a
bare MCAP file, read with the pure-Python `rosbags` library (no ROS install).

`read_rosbag(bag, scan=..., odom=...)` reads three kinds of message, one topic each, in one pass:

- `sensor_msgs/LaserScan` -> the scans. `angle_min` -> `scan_angle_min`, `angle_increment` ->
  `scan_angle_increment` (a negative increment, a clockwise scanner, is turned round: the beams
  reversed), `range_max` -> `scan_max_range` (the largest of the bag's); a reading outside
  [range_min, range_max), inf or NaN becomes NaN (no return). The values are the message's
  float32 ones, widened. Every scan must have the first one's beam count and angles (an error
  names the message that differs).
- `nav_msgs/Odometry` -> the odometry, as `odometry="twist"` (default) says: a "unicycle"
  vehicle with `odo_speed` = twist.twist.linear.x and `odo_yaw_rate` = twist.twist.angular.z
  (the twist is in the robot's frame, the message's child_frame_id), or `odometry="pose"`: a
  "pose-increment" vehicle with `odo_pose` = [position x, y, yaw of the orientation] from
  pose.pose (datasets/FORMAT.md, "The vehicle"; the filter's models are `slam.motion`).
- `sensor_msgs/NavSatFix` (optional, `gps=`) -> `gps_t`, `gps_xy`: local metres, x east and y
  north, by `local_metres` (an equirectangular projection about the first fix, error bound
  there), and `gps_origin`: that fix's latitude, longitude and altitude. Fixes with status
  < 0 (no fix) or a non-finite position are dropped and counted.
  The fixes' `position_covariance` is **not kept**: the sequence format has no place for a GPS
  covariance (`gps_xy` only; a run's start takes its GPS uncertainty from the configuration's
  `[start] gps_sigma_m`).

Time: every time is the message's header stamp (integer nanoseconds), less an origin: the
earliest stamp of the topics read, rounded down to a whole second (`RosbagRun.time_origin_ns`,
also written into the sequence's name). So times keep their nanoseconds (a float64 of
seconds since 1970 would keep 0.24 us) and their sub-second digits. Each topic's stamps must be
strictly increasing in the order the bag holds the messages.

The laser's pose in the vehicle frame: `laser_pose=(x, y, yaw)`, else from `/tf_static`: the
chain of static transforms from the robot's frame (the odometry's child_frame_id, else
`base_link`, else `base_footprint`) to the scan's frame_id, composed in 3D and projected onto the
plane (x, y and the yaw of the laser's x-axis). A laser mounted upside down (its z-axis down)
sees the world mirrored: its beams are mirrored into an upright laser's. The GPS antenna is
placed the same way when /tf_static has its frame (else `gps_pose` is left out: the antenna is
taken at the laser, datasets/FORMAT.md).

Errors are `DataError` (or `ConfigError` for a bad argument) with a message that says what to
do: a missing topic lists the topics there are, with their types.
"""

from __future__ import annotations

import json
import logging
import math
import os
import stat
import tempfile
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from experiments.errors import ConfigError, DataError
from experiments.io.writers import file_kind
from slam import Sequence, SlamConfig, SlamError
from slam.checks import check_runnable

__all__ = [
    "BASE_FRAMES",
    "MESSAGE_TYPES",
    "ODOMETRY_SOURCES",
    "TF_STATIC",
    "RosbagRun",
    "bag_inputs",
    "bag_topics",
    "local_metres",
    "read_rosbag",
]

log = logging.getLogger(__name__)

# the message type each role reads (rosbags names ROS 1 types the ROS 2 way: pkg/msg/Name)
MESSAGE_TYPES = {
    "scan": "sensor_msgs/msg/LaserScan",
    "odom": "nav_msgs/msg/Odometry",
    "gps": "sensor_msgs/msg/NavSatFix",
    "tf": "tf2_msgs/msg/TFMessage",
}
TF_STATIC = "/tf_static"
# --odometry: the part of nav_msgs/Odometry used -> the sequence's vehicle model
ODOMETRY_SOURCES = {"twist": "unicycle", "pose": "pose-increment"}
BASE_FRAMES = ("base_link", "base_footprint")  # the robot's frame when the odometry names none
# WGS84 ellipsoid: semi-major axis (m) and first eccentricity squared
WGS84_A_M = 6378137.0
WGS84_E2 = 6.69437999014e-3
_SIDEWAYS_MPS = 0.05  # a twist's linear.y beyond this is worth a warning: a unicycle has none
_STILL_M = 0.1  # odometry that moves less than this over the whole bag counts as standing still
_TILT_WARN_RAD = math.radians(2.0)
MAX_MOUNT_M = 100.0  # a given laser pose's |x|, |y| in the robot's frame: a sensor on the robot


@dataclass(frozen=True)
class RosbagRun:
    """What `read_rosbag` made: the sequence, and how.

    time_origin_ns: the ROS time (ns) of t = 0 in the sequence.
    laser_pose_from: where the laser pose came from: "given", or "from /tf_static: base_link ->
        laser" (with " (mirrored: mounted upside down)" when it was).
    messages: messages read per topic.
    gps_dropped: NavSatFix messages left out (status < 0, no fix; or a non-finite position).
    """

    sequence: Sequence
    time_origin_ns: int
    laser_pose_from: str
    messages: dict[str, int] = field(default_factory=dict)
    gps_dropped: int = 0

    def summary(self) -> str:
        """One line: what the sequence holds and where the laser pose came from."""
        s = self.sequence
        parts = [f"{s.n_scans} scans", f"{s.odo_t.size} odometry samples ({self.odometry})"]
        if s.gps_t is not None:
            dropped = f" ({self.gps_dropped} without a fix dropped)" if self.gps_dropped else ""
            parts.append(f"{s.gps_t.size} GPS fixes{dropped}")
        x, y, yaw = (f"{float(v):.6g}" for v in s.laser_pose)
        return (
            ", ".join(parts)
            + f"; laser pose ({x}, {y}, {yaw}) {self.laser_pose_from}"
            + f"; t = 0 at ROS time {_ros_time(self.time_origin_ns)} s"
        )

    @property
    def odometry(self) -> str:
        """ "twist" or "pose": the part of the Odometry messages the sequence holds."""
        model = self.sequence.vehicle.model
        return next(k for k, v in ODOMETRY_SOURCES.items() if v == model)


# ---------------------------------------------------------------------------------------------
# opening a bag


def _bag_paths(path: Path) -> Path:
    """The path rosbags opens: a ROS 1 `.bag` file, or a ROS 2 bag folder (the folder of a
    `.db3` / `.mcap` file given directly); a bare `.mcap` file is left as it is. Anything but a
    regular file or a folder (a FIFO, a device: reading it could wait forever) is refused, and
    so is a bag folder holding one."""
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    _refuse_special(path)
    if path.is_dir():
        with os.scandir(path) as entries:
            for e in entries:
                _refuse_special(Path(e.path))
    if path.is_file() and path.suffix in (".db3", ".mcap"):
        if (path.parent / "metadata.yaml").is_file():
            return path.parent
        if path.suffix == ".mcap":
            return path  # a bare MCAP file: `_mcap_as_bag`
        raise DataError(
            f"{path}: a ROS 2 storage file without the bag's metadata.yaml beside it; give the "
            "bag folder (`ros2 bag reindex FOLDER` rebuilds a lost metadata.yaml)"
        )
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        raise DataError(f"{path}: a folder without metadata.yaml, so not a ROS 2 bag")
    if path.is_file() and path.suffix != ".bag":
        raise DataError(
            f"{path}: not a ROS bag (expected a ROS 1 .bag file, a ROS 2 bag folder holding "
            "metadata.yaml and a .db3 or .mcap file, or an .mcap file)"
        )
    return path


@contextmanager
def _open_bag(path: Path) -> Iterator:
    """An open `rosbags.highlevel.AnyReader`, with the library's errors as `DataError`. Bags
    without message definitions (ROS 2 before Iron) are read with the Humble (or Noetic) types,
    which are the same for the messages read here."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = _bag_paths(path)
    store = get_typestore(Stores.ROS1_NOETIC if bag.suffix == ".bag" else Stores.ROS2_HUMBLE)
    with ExitStack() as stack:
        try:
            if bag.suffix == ".mcap":
                bag = stack.enter_context(_mcap_as_bag(bag))
            reader = AnyReader([bag], default_typestore=store)
            reader.open()
        except DataError:
            raise
        except Exception as exc:  # rosbags' own errors, and whatever a corrupt file provokes
            raise DataError(f"{path}: cannot read the bag: {_why(exc)}") from exc
        try:
            yield reader
        finally:
            reader.close()


@contextmanager
def _mcap_as_bag(path: Path) -> Iterator[Path]:
    """A bare MCAP file (no rosbag2 metadata.yaml beside it, as Foxglove and the `mcap` tools
    write them) as a ROS 2 bag folder: a temporary folder holding a link to the file and the
    metadata.yaml rosbags reads, made from the file's own index (topics, types, counts)."""
    from rosbags.rosbag2.storage_mcap import McapReader

    storage = McapReader(path)
    storage.open()
    try:
        conns, meta = list(storage.connections), storage.metadata  # close() empties the list
    finally:
        storage.close()
    span = {"duration": {"nanoseconds": max(meta.duration - 1, 0)}}
    start = {"starting_time": {"nanoseconds_since_epoch": meta.start_time}}
    topics = [
        {
            "message_count": c.msgcount,
            "topic_metadata": {
                "name": c.topic,
                "type": c.msgtype,
                "serialization_format": "cdr",
                "offered_qos_profiles": [],
                "type_description_hash": "",
            },
        }
        for c in conns
    ]
    count = {"message_count": meta.message_count}
    info = {
        "version": 9,
        "storage_identifier": "mcap",
        "relative_file_paths": [path.name],
        "files": [{"path": path.name, **span, **start, **count}],
        "topics_with_message_count": topics,
        "compression_format": "",
        "compression_mode": "",
        "custom_data": None,
        "ros_distro": "",
    }
    with tempfile.TemporaryDirectory(prefix="trunkslam_mcap_") as tmp:
        folder = Path(tmp)
        (folder / path.name).symlink_to(path.resolve())
        meta_yaml = {"rosbag2_bagfile_information": info | span | start | count}
        (folder / "metadata.yaml").write_text(json.dumps(meta_yaml), encoding="utf-8")  # YAML 1.2
        yield folder


def _refuse_special(path: Path) -> None:
    """`DataError` when `path` (links followed) is neither a regular file nor a folder."""
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        raise DataError(f"{path}: cannot be read ({exc.strerror})") from None
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise DataError(
            f"{path}: is {file_kind(mode)}, not a file or a folder; a bag is read from files "
            "(copy it to one first)"
        )


def bag_inputs(path: Path | str) -> list[Path]:
    """The paths `read_rosbag(path)` reads, for the output checks (`check_outputs`): the path,
    and the bag folder when it is a storage file inside one (its metadata.yaml, its other
    files)."""
    path = Path(path)
    found = [path]
    if path.suffix in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file():
        found.append(path.parent)
    return found


def _reader_errors() -> tuple[type[BaseException], ...]:
    """What rosbags raises for a file it cannot read (a truncated bag, a corrupt database, a
    message that does not deserialise): its own errors, and the file's."""
    import sqlite3
    import struct

    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError

    return (
        AnyReaderError,
        Reader1Error,
        Reader2Error,
        SerdeError,
        sqlite3.Error,
        struct.error,
        OSError,
        EOFError,
    )


def _why(exc: Exception) -> str:
    """A reader's exception in words: its message, with its type when that is not one of the
    library's own errors (a bare `TypeError: ord() ...` says nothing to a user)."""
    if isinstance(exc, _reader_errors()):
        return str(exc)
    return f"the file is damaged or not what its name says ({type(exc).__name__}: {exc})"


def _topic_table(reader) -> dict[str, tuple[str | None, int]]:
    return {name: (info.msgtype, info.msgcount) for name, info in reader.topics.items()}


def bag_topics(path: Path | str) -> dict[str, tuple[str | None, int]]:
    """{topic: (message type, message count)} of a bag (type None: several types)."""
    with _open_bag(Path(path)) as reader:
        return _topic_table(reader)


def _listing(topics: dict[str, tuple[str | None, int]]) -> str:
    return ", ".join(
        f"{t} ({ty or 'several types'}, {n} messages)" for t, (ty, n) in topics.items()
    )


def _pick(path: Path, topics, role: str, name: str) -> str:
    """The bag's topic for `name` (a missing leading slash is added), checked: there, of the
    role's message type, not empty."""
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{role} topic: expected a topic name, got {name!r}")
    if name not in topics and "/" + name in topics:
        name = "/" + name
    if name not in topics:
        raise DataError(f"{path}: no topic {name!r}; the bag's topics: {_listing(topics)}")
    msgtype, count = topics[name]
    want = MESSAGE_TYPES[role]
    if msgtype != want:
        raise DataError(f"{path}: topic {name} is {msgtype}, expected {want}")
    if count == 0:
        raise DataError(f"{path}: topic {name} ({want}) has no messages")
    return name


# ---------------------------------------------------------------------------------------------
# one collector per topic: each message's fields, in bag order


def _stamp_ns(msg) -> int:
    s = msg.header.stamp
    return int(s.sec) * 1_000_000_000 + int(s.nanosec)


def _frame(frame_id: str) -> str:
    return frame_id.lstrip("/")  # ROS 1 frames may carry a leading slash


class _Scans:
    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []
        self.ranges: list[np.ndarray] = []
        self.layout: tuple[int, float, float] | None = None  # beams, angle_min, increment
        self.frame = ""
        self.range_max = 0.0

    def add(self, k: int, msg) -> None:
        r = np.asarray(msg.ranges, dtype=np.float32)
        layout = (r.size, float(msg.angle_min), float(msg.angle_increment))
        if self.layout is None:
            if r.size == 0 or layout[2] == 0 or not all(map(math.isfinite, layout[1:])):
                raise DataError(
                    f"{self.topic}: message 0 has {r.size} beams from {layout[1]!r} rad in steps "
                    f"of {layout[2]!r} rad; a scan needs beams and a finite, non-zero increment"
                )
            self.layout, self.frame = layout, _frame(msg.header.frame_id)
        elif layout != self.layout:
            n, a, inc = self.layout
            raise DataError(
                f"{self.topic}: message {k} has {layout[0]} beams from {layout[1]!r} rad in steps "
                f"of {layout[2]!r} rad, the first message {n} from {a!r} in steps of {inc!r}; a "
                "sequence needs one beam layout (convert the parts separately)"
            )
        lo, hi = float(msg.range_min), float(msg.range_max)
        if not hi > 0:
            raise DataError(f"{self.topic}: message {k} has range_max {hi!r}; must be > 0 m")
        self.range_max = max(self.range_max, hi)
        self.ranges.append(np.where((r >= lo) & (r < hi), r, np.float32(np.nan)))  # NaN: no return
        self.stamps.append(_stamp_ns(msg))


class _Odometry:
    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []
        self.rows: list[tuple[float, ...]] = []  # v, omega, sideways v, x, y, yaw, |q|
        self.child_frame = ""

    def add(self, k: int, msg) -> None:
        if k == 0:
            self.child_frame = _frame(msg.child_frame_id)
        tw, p = msg.twist.twist, msg.pose.pose
        q = p.orientation
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        # the heading of the rotated x-axis; independent of the quaternion's scale
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), q.w**2 + q.x**2 - q.y**2 - q.z**2)
        v, w, vy = tw.linear.x, tw.angular.z, tw.linear.y
        self.rows.append((v, w, vy, p.position.x, p.position.y, yaw, norm))
        self.stamps.append(_stamp_ns(msg))


class _Fixes:
    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.stamps: list[int] = []  # every message's, for the order check
        self.kept: list[tuple[int, float, float, float]] = []  # stamp, lat, lon, altitude (deg, m)
        self.frame = ""
        self.dropped = 0
        self.covariance = False

    def add(self, k: int, msg) -> None:
        stamp = _stamp_ns(msg)
        self.stamps.append(stamp)
        if not self.frame:
            self.frame = _frame(msg.header.frame_id)
        self.covariance |= int(msg.position_covariance_type) > 0
        lat, lon = float(msg.latitude), float(msg.longitude)
        if int(msg.status.status) < 0 or not (math.isfinite(lat) and math.isfinite(lon)):
            self.dropped += 1
            return
        if abs(lat) > 90.0 or abs(lon) > 180.0:
            raise DataError(
                f"{self.topic}: message {k} has latitude {lat!r} deg, longitude {lon!r} deg; "
                "a fix is within +-90 deg of latitude and +-180 deg of longitude"
            )
        self.kept.append((stamp, lat, lon, float(msg.altitude)))


class _StaticTf:
    """The /tf_static transforms: {(parent, child): 4 x 4 T_parent_child} (a later one replaces
    an earlier one of the same pair)."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.edges: dict[tuple[str, str], np.ndarray] = {}

    def add(self, k: int, msg) -> None:
        for ts in msg.transforms:
            t, q = ts.transform.translation, ts.transform.rotation
            T = np.eye(4)
            T[:3, :3] = _rotation(self.topic, k, (q.x, q.y, q.z, q.w))
            T[:3, 3] = (t.x, t.y, t.z)
            self.edges[(_frame(ts.header.frame_id), _frame(ts.child_frame_id))] = T

    def chain(self, source: str, target: str) -> np.ndarray | None:
        """T_source_target composed along the transforms (either way round), or None."""
        graph: dict[str, list[tuple[str, np.ndarray]]] = {}
        for (a, b), T in self.edges.items():
            graph.setdefault(a, []).append((b, T))
            graph.setdefault(b, []).append((a, _inverse(T)))
        seen, todo = {source: np.eye(4)}, deque([source])
        while todo:
            a = todo.popleft()
            for b, T in graph.get(a, []):
                if b not in seen:
                    seen[b] = seen[a] @ T
                    todo.append(b)
        return seen.get(target)

    def frames(self) -> list[str]:
        return sorted({f for pair in self.edges for f in pair})


def _rotation(topic: str, k: int, q: tuple[float, float, float, float]) -> np.ndarray:
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not 0.5 < n < 2.0:
        raise DataError(f"{topic}: message {k} holds a rotation quaternion of norm {n:.3g}")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _inverse(T: np.ndarray) -> np.ndarray:
    inv = np.eye(4)
    inv[:3, :3] = T[:3, :3].T
    inv[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return inv


# ---------------------------------------------------------------------------------------------
# reading


def read_rosbag(
    path: Path | str,
    *,
    scan: str,
    odom: str,
    gps: str | None = None,
    laser_pose: tuple[float, float, float] | None = None,
    odometry: str = "twist",
    progress: Callable[[str, int, int], None] | None = None,
) -> RosbagRun:
    """The bag at `path` as a `Sequence` (module docstring: what is read and how).

    path: a ROS 1 `.bag`, a ROS 2 bag folder (sqlite3 or MCAP storage), the `.db3` / `.mcap`
        file inside one, or a bare `.mcap` file (ROS 2 profile).
    scan, odom, gps: the topics of the LaserScan, Odometry and (optional) NavSatFix messages.
    laser_pose: (x m, y m, yaw rad) of the laser in the vehicle frame; None: from /tf_static.
    odometry: "twist" (a unicycle's speed and yaw rate) or "pose" (pose increments).
    progress: callback(description, messages read, messages to read), now and then.
    """
    path = Path(path)
    if odometry not in ODOMETRY_SOURCES:
        raise ConfigError(f"odometry: expected one of {sorted(ODOMETRY_SOURCES)}, got {odometry!r}")
    if laser_pose is not None:
        laser_pose = _given_pose(laser_pose)
    with _open_bag(path) as reader:
        topics = _topic_table(reader)
        if sum(n for _, n in topics.values()) == 0:
            raise DataError(f"{path}: the bag holds no messages")
        names = {"scan": scan, "odom": odom} | ({} if gps is None else {"gps": gps})
        roles = {role: _pick(path, topics, role, name) for role, name in names.items()}
        if topics.get(TF_STATIC, (None, 0))[0] == MESSAGE_TYPES["tf"]:
            roles["tf"] = TF_STATIC
        kinds = {"scan": _Scans, "odom": _Odometry, "gps": _Fixes, "tf": _StaticTf}
        got = {role: kinds[role](topic) for role, topic in roles.items()}
        counts = _read(reader, {topic: got[role] for role, topic in roles.items()}, path, progress)
    for role in ("scan", "odom", "gps"):
        if role in got:
            _check_stamps(got[role].topic, got[role].stamps)
    return _assemble(path, got, counts, laser_pose, odometry)


def _given_pose(pose) -> tuple[float, float, float]:
    try:
        p = tuple(float(v) for v in pose)
    except (TypeError, ValueError, OverflowError):
        p = ()
    if len(p) != 3 or not all(map(math.isfinite, p)):
        raise ConfigError(f"laser_pose: expected three finite numbers x, y, yaw, got {pose!r}")
    if max(abs(p[0]), abs(p[1])) > MAX_MOUNT_M:
        raise ConfigError(
            f"laser_pose: the laser at ({p[0]:.6g}, {p[1]:.6g}) m is more than {MAX_MOUNT_M:g} m "
            "from the robot's frame (MAX_MOUNT_M); give x, y in metres"
        )
    if abs(p[2]) > 2 * math.pi:
        raise ConfigError(
            f"laser_pose: yaw {p[2]:.6g} rad is beyond +-2 pi; give it in radians, not degrees"
        )
    return p


def _read(reader, collectors: dict, path: Path, progress) -> dict[str, int]:
    """Every message of the collectors' topics, in the bag's order, to its collector; returns
    the messages read per topic."""
    conns = [c for c in reader.connections if c.topic in collectors]
    total = sum(c.msgcount for c in conns)
    every = max(1, -(-total // 200))  # at most 200 reports
    counts = dict.fromkeys(collectors, 0)
    desc = f"reading {path.name}"
    if progress is not None:
        progress(desc, 0, total)
    try:
        for done, (conn, _, raw) in enumerate(reader.messages(connections=conns), 1):
            k = counts[conn.topic]
            collectors[conn.topic].add(k, reader.deserialize(raw, conn.msgtype))
            counts[conn.topic] = k + 1
            if progress is not None and (done % every == 0 or done == total):
                progress(desc, done, total)
    except DataError:
        raise
    except Exception as exc:  # as in `_open_bag`: any error of the reader on a corrupt bag
        raise DataError(f"{path}: cannot read the bag's messages: {_why(exc)}") from exc
    empty = [t for t, n in counts.items() if n == 0]
    if empty:
        raise DataError(f"{path}: topic {empty[0]} has no messages that could be read")
    return counts


def _check_stamps(topic: str, stamps: list[int]) -> None:
    s = np.asarray(stamps, dtype=np.int64)
    if s.size and s[0] < 0:
        raise DataError(
            f"{topic}: the header stamp of message 0 is negative ({int(s[0]) / 1e9:.9f} s); a "
            "ROS time is counted from 1970"
        )
    bad = np.flatnonzero(np.diff(s) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        how = "the same as" if s[k] == s[k - 1] else "before"
        raise DataError(
            f"{topic}: the header stamp of message {k} ({_ros_time(int(s[k]))} s) is {how} "
            f"message {k - 1}'s ({_ros_time(int(s[k - 1]))} s); a topic's stamps must be "
            "strictly increasing"
        )


def _ros_time(ns: int) -> str:
    return f"{ns // 1_000_000_000}.{ns % 1_000_000_000:09d}"


def _assemble(path: Path, got: dict, counts, laser_pose, odometry: str) -> RosbagRun:
    """The collectors' contents as a `Sequence`."""
    scans, odo, fixes, tf = got["scan"], got["odom"], got.get("gps"), got.get("tf")
    firsts = [c.stamps[0] for c in (scans, odo, fixes) if c is not None and c.stamps]
    origin = min(firsts) // 1_000_000_000 * 1_000_000_000

    def seconds(stamps) -> np.ndarray:
        return (np.asarray(stamps, dtype=np.int64) - origin) / 1e9  # exact ns -> s, rounded once

    base = _base_frames(odo.child_frame)
    mount, source, mirror = _laser_mount(path, scans.frame, tf, base, laser_pose)
    ranges = np.vstack(scans.ranges).astype(np.float64)
    amin, inc, reverse = _beam_layout(*scans.layout, mirror=mirror)
    if reverse:
        ranges = ranges[:, ::-1]
    reading = _odometry_reading(odo, odometry)
    gps_fields, dropped = _gps_fields(fixes, seconds, tf, base)
    name = (
        f"ROS bag {path.name}: {scans.topic}, {odo.topic} ({odometry})"
        + (f", {fixes.topic}" if fixes is not None else "")
        + f"; t = 0 at ROS time {_ros_time(origin)} s"
    )
    try:
        seq = Sequence(
            scan_t=seconds(scans.stamps),
            scan_ranges=ranges,
            scan_angle_min=amin,
            scan_angle_increment=inc,
            scan_max_range=scans.range_max,
            laser_pose=np.array(mount),
            odo_t=seconds(odo.stamps),
            vehicle={"model": ODOMETRY_SOURCES[odometry]},
            name=name,
            **reading,
            **gps_fields,
        )
        check_runnable(seq, SlamConfig())  # convert never writes what slam would refuse
    except SlamError as exc:
        raise DataError(f"{path}: {exc}") from exc
    return RosbagRun(seq, origin, source, counts, dropped)


def _odometry_reading(odo: _Odometry, odometry: str) -> dict[str, np.ndarray]:
    """The sequence's odometry fields from the part of the messages `odometry` names; a part
    that stays empty while the other moves (a driver that fills only one) is an error."""
    rows = np.asarray(odo.rows, dtype=np.float64)
    twist, pose = rows[:, 0:3], rows[:, 3:6]
    travel = float(np.sum(np.hypot(*np.diff(pose[:, :2], axis=0).T)))
    if odometry == "twist":
        if not np.any(twist[:, :2]) and travel > _STILL_M:
            raise DataError(
                f"{odo.topic}: the twist is zero in every message while the pose moves "
                f"{travel:.3g} m; the driver fills only the pose: use --odometry pose"
            )
        sideways = float(np.max(np.abs(twist[:, 2])))
        if sideways > _SIDEWAYS_MPS:
            log.warning(
                "%s: the twist has a sideways speed (linear.y up to %.3g m/s) that a unicycle "
                "ignores; --odometry pose uses the odometry's own poses",
                odo.topic,
                sideways,
            )
        return {"odo_speed": twist[:, 0], "odo_yaw_rate": twist[:, 1]}
    norm = rows[:, 6]
    bad = np.flatnonzero(np.abs(norm - 1.0) > 0.01)
    if bad.size:
        k = int(bad[0])
        raise DataError(
            f"{odo.topic}: message {k}'s pose orientation is not a unit quaternion (norm "
            f"{norm[k]:.3g}); does the driver fill only the twist? then use --odometry twist"
        )
    if travel <= _STILL_M and np.any(twist[:, :2]):
        dt_s = np.diff(np.asarray(odo.stamps, dtype=np.int64)) / 1e9
        moved = float(np.sum(np.abs(twist[:-1, 0]) * dt_s))
        if moved > _STILL_M:
            raise DataError(
                f"{odo.topic}: the pose stays put while the twist drives {moved:.3g} m; the "
                "driver fills only the twist: use --odometry twist"
            )
    return {"odo_pose": pose}


def _base_frames(child_frame: str) -> tuple[str, ...]:
    return tuple(dict.fromkeys(f for f in (child_frame, *BASE_FRAMES) if f))


def _beam_layout(n: int, amin: float, inc: float, *, mirror: bool) -> tuple[float, float, bool]:
    """(angle_min, increment > 0, reverse the beams?) of an upright, counter-clockwise scan from
    a message's layout; mirror: the laser is upside down, so its angles change sign."""
    if mirror:
        amin, inc = -amin, -inc
    if inc < 0:
        return amin + (n - 1) * inc, -inc, True
    return amin, inc, False


def _laser_mount(path: Path, frame: str, tf, base: tuple[str, ...], given):
    """((x, y, yaw) of the laser in the vehicle frame, where it came from, mirrored?)."""
    if given is not None:
        return given, "given", False
    if tf is None:
        raise DataError(
            f"{path}: no {TF_STATIC} to place the laser (frame {frame!r}) on the robot; give its "
            "pose in the vehicle frame: --laser-pose x,y,yaw (m, m, rad)"
        )
    for b in base:
        T = tf.chain(b, frame)
        if T is not None:
            pose, mirror = _planar(T, f"{b} -> {frame}")
            note = " (mirrored: mounted upside down)" if mirror else ""
            return pose, f"from {TF_STATIC}: {b} -> {frame}{note}", mirror
    raise DataError(
        f"{path}: {TF_STATIC} has no chain of transforms from the robot's frame "
        f"({' or '.join(base)}) to the scan's frame {frame!r}; its frames: {tf.frames()}. Give "
        "the laser's pose in the vehicle frame: --laser-pose x,y,yaw (m, m, rad)"
    )


def _planar(T: np.ndarray, what: str) -> tuple[tuple[float, float, float], bool]:
    """A 3D mounting T_base_sensor as (x, y, yaw of the sensor's x-axis) and whether its z-axis
    points down; a tilted scan plane is treated as level, with a warning."""
    R = T[:3, :3]
    tilt = math.acos(min(1.0, abs(float(R[2, 2]))))
    if tilt > _TILT_WARN_RAD:
        log.warning("%s: tilted %.1f deg from level; taken as level", what, math.degrees(tilt))
    yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))
    return (float(T[0, 3]), float(T[1, 3]), yaw), bool(R[2, 2] < 0)


def _gps_fields(fixes, seconds, tf, base) -> tuple[dict, int]:
    """The fixes as gps_t, gps_xy (and gps_pose when /tf_static places the antenna)."""
    if fixes is None:
        return {}, 0
    if not fixes.kept:
        raise DataError(
            f"{fixes.topic}: none of its {len(fixes.stamps)} fixes is usable (status < 0, no "
            "fix, or a non-finite position)"
        )
    if fixes.dropped:
        log.info("%s: %d fixes without a fix (status < 0) dropped", fixes.topic, fixes.dropped)
    if fixes.covariance:
        log.info(
            "%s: the fixes' position_covariance is not kept (the sequence format has no GPS "
            "covariance; the start uses [start] gps_sigma_m)",
            fixes.topic,
        )
    stamp, lat, lon, alt = (np.array(c) for c in zip(*fixes.kept))
    h0 = float(alt[0]) if math.isfinite(alt[0]) else 0.0
    out = {"gps_t": seconds(stamp), "gps_xy": local_metres(lat, lon, lat[0], lon[0], h0)}
    out["gps_origin"] = np.array([lat[0], lon[0], h0])  # export-map's WGS84 frame
    T = None
    if tf is not None and fixes.frame:
        T = next((t for b in base if (t := tf.chain(b, fixes.frame)) is not None), None)
    if T is not None:
        out["gps_pose"] = np.array([T[0, 3], T[1, 3], 0.0])
    else:
        log.warning(
            "%s: the antenna's frame %r is not in %s: taken at the laser (set [vehicle] "
            "gps_antenna in the configuration if it is elsewhere)",
            fixes.topic,
            fixes.frame,
            TF_STATIC,
        )
    return out, fixes.dropped


def local_metres(lat_deg, lon_deg, lat0_deg: float, lon0_deg: float, h0_m: float = 0.0):
    """(G, 2) [x east, y north] metres of fixes (degrees, WGS84) about (lat0, lon0): the
    equirectangular projection with the ellipsoid's radii of curvature at the origin,

        x = (N0 + h0) cos(lat0) (lon - lon0),   y = (M0 + h0) (lat - lat0)   (radians),

    N0 = a / sqrt(1 - e^2 sin^2 lat0) (prime vertical), M0 = N0 (1 - e^2) / (1 - e^2 sin^2 lat0)
    (meridian), h0 the origin's altitude (a fix at 2 km above the ellipsoid is 3e-4 further).
    Against the local tangent plane (east, north of the origin), the error is second order in
    the distance d from the origin: the parallels converge towards the pole, so a point at
    (x, y) is off by about (x y, x^2 / 2) tan(lat0) / N0, at most d^2 tan|lat0| / (sqrt(3) N0);
    the meridian's changing curvature adds up to d^2 3 e^2 |sin 2 lat0| / (4 M0), and the plane
    itself d^3 / R^2. At 48 degrees latitude that is 1.0 mm within 100 m and 0.10 m within
    1 km (tests/experiments/test_rosbag.py checks the bound against the exact tangent plane);
    it grows with tan(lat0) towards the poles. Longitudes are wrapped, so a run across the
    antimeridian works.
    """
    # differences taken in degrees (exact for nearby values), then turned into radians
    dlat = np.radians(np.asarray(lat_deg, dtype=np.float64) - lat0_deg)
    dlon_deg = np.asarray(lon_deg, dtype=np.float64) - lon0_deg
    dlon_deg = np.where(dlon_deg > 180, dlon_deg - 360, dlon_deg)  # across the antimeridian
    dlon = np.radians(np.where(dlon_deg < -180, dlon_deg + 360, dlon_deg))
    lat0 = math.radians(lat0_deg)
    w = 1.0 - WGS84_E2 * math.sin(lat0) ** 2
    n0 = WGS84_A_M / math.sqrt(w)
    m0 = n0 * (1.0 - WGS84_E2) / w
    return np.stack([(n0 + h0_m) * math.cos(lat0) * dlon, (m0 + h0_m) * dlat], axis=-1)

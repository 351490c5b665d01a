"""Hostile commands (issue 43): the case kinds of the audit that run a whole command rather
than one file reader (tests/hostile.py holds the file formats).

Kinds:

- "rosbag": `trunkslam convert rosbag` on damaged bags (an `.mcap` of its magic bytes, random
  bytes named `.bag`, a metadata.yaml claiming compression, a FIFO), messages that `slam` would
  refuse (a negative stamp, odometry after the last scan, a latitude of 95 deg), extreme
  `--laser-pose` values and `--out` paths inside the bag;
- "links": a symbolic or hard link (or a FIFO) planted at a lock, output or temporary path of
  every command that writes (slam, smooth, export-reference, export-graph, export-map, extract,
  convert, simulate, simulate-drive, sweep, reproduce, report, a benchmark's --out), pointing at
  a user's file or at the command's own input;
- "options": option extremes and odd paths (`--workers 10**30`, `--trees 10**9`, `--chunks
  2.5`, `--dask bogus://x`, `--config /dev/zero`, a sweep file at /dev/urandom, paths whose
  bytes are not UTF-8, a scene name with a NUL byte, ...);
- "closure": the configuration's [closure] section (loop closure on) with each setting at an
  extreme value, run by `slam` on a simulated drive.

`command_cases(kind)` lists a kind's cases (deterministic); `command_verdict(case, folder)` runs
one in this process (typer's runner, a 120 s alarm) and says "clear" (exit 1 or 2, an `error:`
naming what the case says it must, every protected file as it was), "ran" (exit 0 where the
case allows a result: a valid extreme setting), "unclear" (refused without naming it),
"accepted" (exit 0 where a refusal was due, or a protected file changed: a user's file, an
input, a link's target), "traceback" (another exception, or no end within the alarm).
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import signal
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

KINDS = ("rosbag", "links", "options", "closure")
TIMEOUT_S = 120


# ---- a small bag --------------------------------------------------------------------------------

BEAMS = 181
EPOCH_NS = 1_700_000_000_000_000_000


def _ros2_types():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _header(ts, ns: int, frame: str):
    T = ts.types
    sec, nsec = divmod(int(ns), 10**9)
    stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def _scan(ts, ns: int, n: int = BEAMS):
    return ts.types["sensor_msgs/msg/LaserScan"](
        header=_header(ts, ns, "laser"),
        angle_min=-math.pi / 2,
        angle_max=math.pi / 2,
        angle_increment=math.pi / (n - 1) if n > 1 else 0.0,
        time_increment=0.0,
        scan_time=0.2,
        range_min=0.1,
        range_max=80.0,
        ranges=np.full(n, 5.0, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )


def _odom(ts, ns: int, v=1.0, w=0.0, xyq=(0.0, 0.0, 0.0, 1.0)):
    T = ts.types
    x, y, qz, qw = xyq
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=qz, w=qw),
    )
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](
        linear=vec(x=v, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=w)
    )
    return T["nav_msgs/msg/Odometry"](
        header=_header(ts, ns, "odom"),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
    )


def _fix(ts, ns: int, lat=48.137, lon=11.575):
    T = ts.types
    return T["sensor_msgs/msg/NavSatFix"](
        header=_header(ts, ns, "gps"),
        status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=lat,
        longitude=lon,
        altitude=500.0,
        position_covariance=np.zeros(9),
        position_covariance_type=0,
    )


@dataclass(frozen=True)
class BagPlan:
    """What a small bag holds: scan and odometry stamps (ns), fixes (ns, lat, lon), and a
    message-level change (`odom`: keyword arguments of every odometry message)."""

    scan_ns: tuple = tuple(EPOCH_NS + k * 200_000_000 for k in range(4))
    odo_ns: tuple = tuple(EPOCH_NS + k * 100_000_000 for k in range(8))
    fixes: tuple = (
        (EPOCH_NS + 100_000_000, 48.137, 11.575),
        (EPOCH_NS + 500_000_000, 48.137, 11.5751),
    )
    odom: dict = field(default_factory=dict)
    beams: int = BEAMS


def write_bag(path: Path, plan: BagPlan = BagPlan(), storage: str = "sqlite3") -> Path:
    """A ROS 2 bag folder (sqlite3 or MCAP storage) of `plan`: /scan, /odom, /fix."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = _ros2_types()
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    rows = [(ns, "scan", _scan(ts, ns, plan.beams)) for ns in plan.scan_ns]
    rows += [(ns, "odom", _odom(ts, ns, **plan.odom)) for ns in plan.odo_ns]
    rows += [(ns, "fix", _fix(ts, ns, lat, lon)) for ns, lat, lon in plan.fixes]
    types = {"scan": "sensor_msgs/msg/LaserScan", "odom": "nav_msgs/msg/Odometry",
             "fix": "sensor_msgs/msg/NavSatFix"}  # fmt: skip
    w = Writer(path, version=9, storage_plugin=plugin)
    w.open()
    try:
        conns = {k: w.add_connection(f"/{k}", t, typestore=ts) for k, t in types.items()}
        for i, (_, kind, msg) in enumerate(sorted(rows, key=lambda r: r[0])):
            w.write(conns[kind], EPOCH_NS + i, ts.serialize_cdr(msg, types[kind]))
    finally:
        w.close()
    return path


# ---- cases and verdicts -----------------------------------------------------------------------


@dataclass(frozen=True)
class CommandCase:
    """One hostile command: its kind, a label, what its error must name, and how to set it up
    (build(folder) -> (arguments, protected paths[, the name the error must hold when known only
    then])). ok_if_runs: exit 0 is a correct outcome
    (a valid extreme setting); protected: files that must be byte for byte as they were (and
    links that must still be links)."""

    kind: str
    label: str
    key: str
    build: Callable[[Path], tuple[list, list[Path]]]
    ok_if_runs: bool = False

    def __repr__(self) -> str:
        return f"{self.kind}: {self.label}"


class _Hang(Exception):
    pass


def _state(p: Path):
    """What a protected path is now: its kind and (for a file) its bytes' hash."""
    try:
        if p.is_symlink():
            return ("link", os.readlink(p), _state(p.resolve()) if p.exists() else None)
        if p.is_file():
            return ("file", hashlib.sha256(p.read_bytes()).hexdigest())
        if p.is_dir():
            return ("dir", tuple(sorted((q.name, _state(q)) for q in p.iterdir())))
        return ("other" if p.exists() else "absent",)
    except OSError as exc:
        return ("error", str(exc))


def run_cli(args: list, timeout_s: float = TIMEOUT_S):
    """`trunkslam ARGS` in this process: (exit code, output, exception or None); a run that
    does not end within `timeout_s` raises `_Hang`."""
    from typer.testing import CliRunner

    from experiments.cli import app

    def alarm(signum, frame):
        raise _Hang(f"no end within {timeout_s:g} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(int(timeout_s))
    try:
        res = CliRunner().invoke(app, [a if isinstance(a, str) else os.fspath(a) for a in args])
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    exc = res.exception if not isinstance(res.exception, SystemExit) else None
    return res.exit_code, res.output, exc


def command_verdict(case: CommandCase, folder: Path) -> tuple[str, str]:
    """(verdict, detail); see the module doc."""
    folder.mkdir(parents=True, exist_ok=True)
    args, protected, *named = case.build(folder)
    key = named[0] if named else case.key  # a name known once the case is built
    before = {p: _state(p) for p in protected}
    try:
        code, out, exc = run_cli(args)
    except _Hang as hang:
        return "traceback", f"hang: {hang}"
    changed = [str(p) for p in protected if _state(p) != before[p]]
    if isinstance(exc, _Hang):
        return "traceback", f"hang: {exc}"
    if exc is not None:
        return "traceback", f"{type(exc).__name__}: {exc}"[:300]
    if changed:
        return "accepted", f"changed {changed[0]} (exit {code}): {out[-200:]}"
    if code == 0:
        return ("ran", out[-200:]) if case.ok_if_runs else ("accepted", out[-200:])
    if code in (1, 2) and "Traceback" not in out and key in _flat(out):
        return "clear", out
    return "unclear", out


def _flat(text: str) -> str:
    """Output with typer's box drawing and line breaks taken out (usage errors are boxed)."""
    for ch in "│╭╮╰╯─":
        text = text.replace(ch, " ")
    return " ".join(text.split())


# ---- shared inputs ------------------------------------------------------------------------------


@functools.cache
def _drive_bytes(n_scans: int = 12) -> bytes:
    """A simulated drive's sequence file (12 scans, GPS and truth)."""
    from experiments.io.sequence_file import save_sequence
    from experiments.sim import CycabParams, simulate_cycab_run

    seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=n_scans))
    with tempfile.TemporaryDirectory() as d:
        return save_sequence(seq, Path(d) / "drive.npz").read_bytes()


def drive(folder: Path, n_scans: int = 12) -> Path:
    p = folder / "drive.npz"
    p.write_bytes(_drive_bytes(n_scans))
    return p


def precious(folder: Path) -> Path:
    p = folder / "thesis.tex"
    p.write_text("\\chapter{Results}\nweeks of work\n")
    return p


@functools.cache
def _slam_run_files() -> dict[str, bytes]:
    """The files of a `slam` output folder of the drive (for `smooth`)."""
    with tempfile.TemporaryDirectory() as d:
        code, out, exc = run_cli(["slam", drive(Path(d)), "--out", Path(d) / "run"])
        assert code == 0 and exc is None, out
        return {p.name: p.read_bytes() for p in (Path(d) / "run").iterdir()}


def slam_run(folder: Path) -> Path:
    run = folder / "run"
    run.mkdir()
    for name, data in _slam_run_files().items():
        (run / name).write_bytes(data)
    return run


SWEEP = 'study = "association"\ntrials = 1\nseed = 1\n[base]\n"sim.n_scans" = 4\n'
SWEEP += "[grid]\ngate_prob = [0.9]\n[executor]\nworkers = 1\n"
NUL_SWEEP = 'study = "slam"\ntrials = 1\n[base]\nscene = "tree\\u0000park"\n"cycab.n_scans" = 3\n'
NUL_SWEEP += '[grid]\n"cycab.range_sigma_m" = [0.01]\n[executor]\nworkers = 1\n'


# ---- kind "rosbag" ------------------------------------------------------------------------------

ROS_ARGS = ["--scan", "/scan", "--odom", "/odom", "--gps", "/fix", "--laser-pose", "1,0,0"]


def _convert(bag: Path, folder: Path, *extra, out: Path | None = None) -> list:
    out = out if out is not None else folder / "seq.npz"
    extra = list(extra)
    if "--laser-pose" in extra:  # the case's pose replaces the default one
        base = ROS_ARGS[:-2]
    else:
        base = ROS_ARGS
    return ["convert", "rosbag", bag, *base, *extra, "--out", out]


def _protect_bag(bag: Path, out: Path) -> list[Path]:
    files = [bag] if not bag.is_dir() else [bag, *sorted(bag.iterdir())]
    return [*files, out]


def _bag_case(label, key, make, *extra, out=None, ok_if_runs=False) -> CommandCase:
    """make(folder) -> the bag path; the command converts it to folder/seq.npz (or `out`)."""

    def build(folder: Path):
        bag = make(folder)
        dest = out(folder, bag) if out else folder / "seq.npz"
        return _convert(bag, folder, *extra, out=dest), _protect_bag(bag, dest)

    return CommandCase("rosbag", label, key, build, ok_if_runs)


def _file(name: str, data: bytes):
    def make(folder: Path) -> Path:
        p = folder / name
        p.write_bytes(data)
        return p

    return make


def _bag(plan: BagPlan = BagPlan(), storage="sqlite3", after=None):
    def make(folder: Path) -> Path:
        p = write_bag(folder / "bag", plan, storage)
        return after(p) if after else p

    return make


def _metadata(change: Callable[[str], str]):
    def after(bag: Path) -> Path:
        meta = bag / "metadata.yaml"
        meta.write_text(change(meta.read_text()))
        return bag

    return after


def _replace_storage(data: bytes):
    def after(bag: Path) -> Path:
        for p in bag.glob("*.db3"):
            p.write_bytes(data)
        return bag

    return after


def _fifo_at(name: str):
    def after(bag: Path) -> Path:
        p = bag / name
        p.unlink()
        os.mkfifo(p)
        return bag

    return after


def _fifo_file(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _written(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _fifo_bag(folder: Path) -> Path:
    p = folder / "pipe.bag"
    os.mkfifo(p)
    return p


def _compression(fmt: str, mode: str):
    def change(text: str) -> str:
        text = text.replace("compression_format: ''", f"compression_format: {fmt}")
        return text.replace("compression_mode: ''", f"compression_mode: {mode}")

    return change


def rosbag_cases() -> list[CommandCase]:
    junk = np.random.default_rng(43).bytes(4096)
    out = _bag_file_cases(junk) + _bag_content_cases()
    if os.geteuid() != 0:
        out.append(_bag_case("the .db3 unreadable", "bag", _bag(after=_chmod0("bag.db3"))))
    return out


def _bag_file_cases(junk: bytes) -> list[CommandCase]:
    """Bags that are not bags: the files, their metadata and their storage damaged."""
    return [
        _bag_case("an .mcap of its magic bytes", "mcap.mcap", _file("mcap.mcap", b"\x89MCAP0\r\n")),
        _bag_case("random bytes named .bag", "rand.bag", _file("rand.bag", junk)),
        _bag_case("an empty .bag", "empty.bag", _file("empty.bag", b"")),
        _bag_case(
            "a ROS 1 header and nothing else", "head.bag", _file("head.bag", b"#ROSBAG V2.0\n")
        ),  # fmt: skip
        _bag_case("random bytes named .mcap", "rand.mcap", _file("rand.mcap", junk)),
        _bag_case("a FIFO named .bag", "pipe.bag", _fifo_bag),
        _bag_case(
            "metadata.yaml claims zstd (file)",
            "bag",
            _bag(after=_metadata(_compression("zstd", "FILE"))),
        ),  # fmt: skip
        _bag_case(
            "metadata.yaml claims zstd (message)",
            "bag",
            _bag(after=_metadata(_compression("zstd", "MESSAGE"))),
        ),  # fmt: skip
        _bag_case(
            "metadata.yaml claims lz4", "bag", _bag(after=_metadata(_compression("lz4", "FILE")))
        ),  # fmt: skip
        _bag_case(
            "metadata.yaml of binary junk",
            "bag",
            _bag(after=_metadata(lambda t: junk.decode("latin-1"))),
        ),  # fmt: skip
        _bag_case("metadata.yaml empty", "bag", _bag(after=_metadata(lambda t: ""))),
        _bag_case(
            "metadata.yaml nested 10,000 deep",
            "bag",
            _bag(after=_metadata(lambda t: "[" * 10_000 + "]" * 10_000)),
        ),  # fmt: skip
        _bag_case("metadata.yaml a FIFO", "metadata.yaml", _bag(after=_fifo_at("metadata.yaml"))),
        _bag_case("the .db3 a FIFO", "bag.db3", _bag(after=_fifo_at("bag.db3"))),
        _bag_case("the .db3 random bytes", "bag", _bag(after=_replace_storage(junk))),
        _bag_case("the .db3 empty", "bag", _bag(after=_replace_storage(b""))),
    ]


def _bag_content_cases() -> list[CommandCase]:
    """Valid bags with bad contents (stamps, values), bad options and outputs."""
    later = BagPlan(odo_ns=tuple(EPOCH_NS + 2_000_000_000 + k * 100_000_000 for k in range(8)))
    negative = BagPlan(scan_ns=(-1_000_000_000,) + BagPlan().scan_ns[1:])
    return [
        _bag_case("a negative scan stamp", "negative", _bag(negative)),
        _bag_case("odometry only after the last scan", "odometry", _bag(later)),
        _bag_case(
            "a fix at latitude 95 deg",
            "latitude",
            _bag(BagPlan(fixes=((EPOCH_NS + 100_000_000, 95.0, 11.575),))),
        ),  # fmt: skip
        _bag_case(
            "a fix at longitude 200 deg",
            "longitude",
            _bag(BagPlan(fixes=((EPOCH_NS + 100_000_000, 48.0, 200.0),))),
        ),  # fmt: skip
        _bag_case("odometry speed 1e300", "odo_speed", _bag(BagPlan(odom={"v": 1e300}))),
        _bag_case("odometry yaw rate NaN", "odo_yaw_rate", _bag(BagPlan(odom={"w": math.nan}))),
        _bag_case(
            "a pose 1e300 m away (--odometry pose)",
            "odo_pose",
            _bag(BagPlan(odom={"v": 0.0, "xyq": (1e300, 0.0, 0.0, 1.0)})),
            "--odometry",
            "pose",
        ),  # fmt: skip
        _bag_case("a scan of one beam", "beams", _bag(BagPlan(beams=1))),
        _bag_case("--laser-pose 1e300,0,0", "laser_pose", _bag(), "--laser-pose", "1e300,0,0"),
        _bag_case("--laser-pose 0,0,1e9", "laser_pose", _bag(), "--laser-pose", "0,0,1e9"),
        _bag_case("--laser-pose nan,0,0", "--laser-pose", _bag(), "--laser-pose", "nan,0,0"),
        _bag_case("--laser-pose 0,0,180 (degrees)", "degrees", _bag(), "--laser-pose", "0,0,180"),
        _bag_case("--gps an odometry topic", "/odom", _bag(), "--gps", "/odom"),
        _bag_case(
            "--out the bag folder's metadata.yaml (bag as its .db3)",
            "metadata.yaml",
            lambda f: _bag()(f) / "bag.db3",
            out=lambda f, bag: bag.parent / "metadata.yaml",
        ),  # fmt: skip
        _bag_case(
            "--out the .db3 itself",
            "bag.db3",
            lambda f: _bag()(f) / "bag.db3",
            out=lambda f, bag: bag,
        ),  # fmt: skip
        _bag_case("--out inside the bag folder", "bag", _bag(), out=lambda f, bag: bag / "s.npz"),
        _bag_case("--out the bag folder", "bag", _bag(), out=lambda f, bag: bag),
        _bag_case(
            "--out a symbolic link to a user's file",
            "seq.npz",
            _bag(),
            out=lambda f, bag: _link(f / "seq.npz", precious(f)),
        ),  # fmt: skip
    ]


def _chmod0(name: str):
    def after(bag: Path) -> Path:
        os.chmod(bag / name, 0)
        return bag

    return after


def _link(at: Path, target: Path) -> Path:
    at.symlink_to(target)
    return at


# ---- kind "links" -------------------------------------------------------------------------------

# how a path is planted: a symbolic link to the target, a hard link to it, or a FIFO
PLANTS = ("symlink", "hard link", "FIFO")


def _plant(at: Path, target: Path, how: str) -> None:
    if how == "symlink":
        at.symlink_to(target)
    elif how == "hard link":
        os.link(target, at)
    else:
        os.mkfifo(at)


def _link_case(command: str, where: str, how: str, to: str, setup) -> CommandCase:
    """setup(folder) -> (arguments, the planted path); the plant points at a user's file or
    at the command's input (`to`: "user" or "input")."""

    # a hard link at an output file is replaced by the new file (a rename), never written
    # through: a result is correct there, so long as the target is unchanged
    replaced = how == "hard link" and "lock" not in where

    def build(folder: Path):
        args, at, the_input = setup(folder)
        target = precious(folder) if to == "user" or the_input is None else the_input
        at.parent.mkdir(parents=True, exist_ok=True)
        _plant(at, target, how)
        return args, [target] if replaced else [target, at], at.name

    label = f"{command}: {how} at {where} -> the {'input' if to == 'input' else 'user file'}"
    return CommandCase("links", label, "", build, ok_if_runs=replaced)


def _lock(out: Path) -> Path:
    return out.parent / f".{out.name}.lock"


def _link_slam(where):
    def setup(f):
        d, out = drive(f), f / "out"
        at = {"--out lock": _lock(out), "--out": out, "--rerun": f / "rec.rrd"}[where]
        extra = ["--rerun", f / "rec.rrd"] if where == "--rerun" else []
        return ["slam", d, "--out", out, *extra], at, d

    return setup


def _link_slam_smooth(f):
    d, out = drive(f), f / "out"
    return ["slam", d, "--out", out, "--smooth"], _lock(out), d


def _link_smooth(where):
    def setup(f):
        run = slam_run(f)
        at = _lock(run) if where == "RUN_DIR lock" else run / where
        if at.exists():
            at.unlink()
        return ["smooth", run], at, run / "run_log.npz"

    return setup


def _link_export(where):
    def setup(f):
        d, out = drive(f), f / "ref"
        return ["export-reference", d, "--out", out], _lock(out) if "lock" in where else out, d

    return setup


def _link_extract(where):
    def setup(f):
        d = drive(f)
        at = f / ("features.json" if where == "--out" else "rec.rrd")
        extra = ["--rerun", f / "rec.rrd"] if where == "--rerun" else []
        return ["extract", d, "--out", f / "features.json", *extra], at, d

    return setup


def _link_simulate(f):
    return ["simulate", "test_yard", "--pose", "0,0,0", "--out", f / "s.npz"], f / "s.npz", None


def _link_simulate_drive(f):
    out = f / "d.npz"
    return ["simulate-drive", "--scans", "3", "--out", out], out, None


def _link_convert(f):
    bag = write_bag(f / "bag")
    out = f / "seq.npz"
    return ["convert", "rosbag", bag, *ROS_ARGS, "--out", out], out, bag / "bag.db3"


def _link_sweep(where):
    def setup(f):
        spec = f / "sw.toml"
        spec.write_text(SWEEP)
        out = f / "sweep"
        return ["sweep", spec, "--out", out], _lock(out) if "lock" in where else out, spec

    return setup


def _link_reproduce(where):
    def setup(f):
        out = f / "results"
        args = ["reproduce", "noise-calibration", "--quick", "--workers", "1", "--out", out]
        return args, _lock(out) if "lock" in where else out, None

    return setup


def _link_bench(f):
    out = f / "bench.md"
    return ["bench", "raycast", "--repeats", "1", "--out", out], out, None


def _link_export_graph(f):
    run = slam_run(f)
    out = f / "run.g2o"
    return ["export-graph", run, "--out", out], out, run / "run_log.npz"


def _link_export_map(f):
    run = slam_run(f)
    out = f / "map.geojson"
    return ["export-map", run, "--out", out], out, run / "map.csv"


def _link_report(where):
    def setup(f):
        bench = f / "bench_results"
        bench.mkdir()
        (bench / "bench_x.md").write_text("A table (a machine)\n\n| a |\n|---|\n| 1 |\n")
        docs = f / "site" / "results"
        docs.parent.mkdir()
        readme = f / "README.md"
        at = readme if where == "--readme" else _lock(docs)
        shown = readme if where == "--readme" else ""
        args = ["report", bench, "--docs", docs, "--readme", shown, "--pages", ""]
        return args, at, bench / "bench_x.md"

    return setup


def _link_setups() -> dict[tuple[str, str], Callable]:
    """(command, planted path's role) -> setup(folder) -> (args, planted path, input)."""
    return {
        ("slam", "--out lock"): _link_slam("--out lock"),
        ("slam", "--out"): _link_slam("--out"),
        ("slam", "--rerun"): _link_slam("--rerun"),
        ("slam --smooth", "--out lock"): _link_slam_smooth,
        ("smooth", "RUN_DIR lock"): _link_smooth("RUN_DIR lock"),
        ("smooth", "smoother.json"): _link_smooth("smoother.json"),
        ("smooth", "trajectory_smoothed.tum"): _link_smooth("trajectory_smoothed.tum"),
        ("smooth", "map_smoothed.csv"): _link_smooth("map_smoothed.csv"),
        ("export-reference", "--out lock"): _link_export("--out lock"),
        ("export-reference", "--out"): _link_export("--out"),
        ("extract", "--out"): _link_extract("--out"),
        ("extract", "--rerun"): _link_extract("--rerun"),
        ("simulate", "--out"): _link_simulate,
        ("simulate-drive", "--out"): _link_simulate_drive,
        ("convert rosbag", "--out"): _link_convert,
        ("sweep", "--out lock"): _link_sweep("--out lock"),
        ("sweep", "--out"): _link_sweep("--out"),
        ("reproduce", "--out lock"): _link_reproduce("--out lock"),
        ("reproduce", "--out"): _link_reproduce("--out"),
        ("bench raycast", "--out"): _link_bench,
        ("export-graph", "--out"): _link_export_graph,
        ("export-map", "--out"): _link_export_map,
        ("report", "--docs lock"): _link_report("--docs lock"),
        ("report", "--readme"): _link_report("--readme"),
    }


def _stale_partial(command: str, setup) -> CommandCase:
    """A symbolic link named as a killed run's temporary folder (`.NAME.partial-PID-XXXX`,
    whose process is gone: removed by the next run) pointing at a user's folder: the link is
    not followed (its folder and files are kept) and the run completes."""

    def build(folder: Path):
        args, out, _ = setup(folder)
        mine = folder / "thesis"
        mine.mkdir()
        precious(mine)
        at = out.parent / f".{out.name}.partial-999999999-abcd"
        at.symlink_to(mine)
        return args, [mine, mine / "thesis.tex"], at.name

    label = f"{command}: symlink at a dead run's temporary folder -> the user's folder"
    return CommandCase("links", label, "", build, ok_if_runs=True)


def links_cases() -> list[CommandCase]:
    out = []
    setups = _link_setups()
    out.append(_stale_partial("slam", setups[("slam", "--out")]))
    out.append(_stale_partial("export-reference", setups[("export-reference", "--out")]))
    for (command, where), setup in _link_setups().items():
        for how in PLANTS:
            if how == "FIFO" and "lock" not in where and where not in ("--out",):
                continue  # a FIFO at an output file: the same check as a link's
            for to in ("user", "input"):
                if how == "FIFO" and to == "input":
                    continue  # a FIFO points at nothing
                if how == "hard link" and "lock" not in where:
                    if command not in ("smooth", "extract", "simulate"):
                        continue  # (an output file's hard link: replaced, never written through)
                out.append(_link_case(command, where, how, to, setup))
    return out


# ---- kind "options" -----------------------------------------------------------------------------

BIG = str(10**30)
NOT_UTF8 = os.fsdecode(b"caf\xe9")  # Latin-1 bytes: not UTF-8 (surrogate-escaped here)


def _opt(label: str, key: str, setup: Callable[[Path], list], ok_if_runs=False) -> CommandCase:
    def build(folder: Path):
        return setup(folder), []

    return CommandCase("options", label, key, build, ok_if_runs)


def _with_drive(*args):
    """setup: the arguments with "DRIVE" replaced by a drive's path and "OUT" by an output."""

    def setup(f: Path) -> list:
        d = drive(f)
        return [d if a == "DRIVE" else f / "out" if a == "OUT" else a for a in args]

    return setup


def _file_of(name: str, data: bytes):
    def make(f: Path) -> Path:
        p = f / name
        p.write_bytes(data)
        return p

    return make


def _deep_sweep(f: Path) -> Path:
    p = f / "deep.toml"
    p.write_text(SWEEP.replace("gate_prob = [0.9]", "gate_prob = " + "[" * 60 + "0.9" + "]" * 60))
    return p


def _sweep_with(text: str):
    def make(f: Path) -> Path:
        p = f / "sw.toml"
        p.write_text(text)
        return p

    return make


def option_cases() -> list[CommandCase]:
    cases = _executor_option_cases() + _input_option_cases() + _kept_table_cases()
    return [_expand(c) for c in cases]


def _executor_option_cases() -> list:
    """Options of where and how work runs: workers, threads, Dask, bench sizes."""
    return [
        _opt("reproduce --workers 10**30", "--workers", lambda f: [
            "reproduce", "noise-calibration", "--workers", BIG, "--out", f / "r"]),
        _opt("sweep --workers 10**30", "--workers", lambda f: [
            "sweep", _sweep_with(SWEEP)(f), "--workers", BIG, "--out", f / "s"]),
        _opt("sweep [executor] workers = 10**30", "workers", lambda f: [
            "sweep", _sweep_with(SWEEP.replace("workers = 1", f"workers = {10**18}"))(f),
            "--out", f / "s"]),
        _opt("bench reproduce --workers 10**30", "--workers", lambda f: [
            "bench", "reproduce", "noise-calibration", "--workers", BIG]),
        _opt("--threads 10**30", "--threads", lambda f: [
            "--threads", BIG, "simulate-drive", "--scans", "2", "--out", f / "d.npz"]),
        _opt("bench slam --trees 10**9", "--trees", lambda f: ["bench", "slam", "--trees",
                                                               str(10**9)]),
        _opt("bench slam --trees 10**30", "--trees", lambda f: ["bench", "slam", "--trees", BIG]),
        _opt("bench smoother --chunks 2.5", "--chunks", lambda f: [
            "bench", "smoother", "--chunks", "2.5"]),
        _opt("bench smoother --chunks 0.5", "--chunks", lambda f: [
            "bench", "smoother", "--chunks", "0.5"]),
        _opt("bench smoother --chunks 1e30", "--chunks", lambda f: [
            "bench", "smoother", "--chunks", "1e30"]),
        _opt("bench smoother --chunks 10**30", "--chunks", lambda f: [
            "bench", "smoother", "--chunks", BIG]),
        _opt("reproduce --dask bogus://x", "--dask", lambda f: [
            "reproduce", "noise-calibration", "--dask", "bogus://x", "--out", f / "r"]),
        _opt("sweep --dask bogus://x", "--dask", lambda f: [
            "sweep", _sweep_with(SWEEP)(f), "--dask", "bogus://x", "--out", f / "s"]),
        _opt("sweep [executor] dask = bogus://x", "dask", lambda f: [
            "sweep", _sweep_with(SWEEP.replace("workers = 1", 'dask = "bogus://x"'))(f),
            "--out", f / "s"]),
        _opt("bench reproduce --dask bogus://x", "--dask", lambda f: [
            "bench", "reproduce", "noise-calibration", "--dask", "bogus://x"]),
    ]  # fmt: skip


def _kept_table_cases() -> list:
    """`bench cold --keep`: what is not a bench cold table, refused before any clone."""
    return [
        _opt("bench cold --keep /dev/zero", "--keep", lambda f: [
            "bench", "cold", "--commands", "check", "--keep", "/dev/zero"]),
        _opt("bench cold --keep a FIFO", "--keep", lambda f: [
            "bench", "cold", "--commands", "check", "--keep", _fifo_file(f / "kept.md")]),
        _opt("bench cold --keep a folder", "--keep", lambda f: [
            "bench", "cold", "--commands", "check", "--keep", f]),
        _opt("bench cold --keep a table of another benchmark", "--keep", lambda f: [
            "bench", "cold", "--commands", "check", "--keep", _written(
                f / "kept.md", "A table (a machine)\n\n| a |\n|---|\n| 1 |\n")]),
    ]  # fmt: skip


def _input_option_cases() -> list:
    """Options naming inputs and outputs (configs, sweeps, scenes, paths) and numeric options."""
    S = ["slam", "DRIVE", "--out", "OUT"]
    U = ["smooth", "RUNUTF8"]
    return [
        _opt("slam --config /dev/zero", "/dev/zero", _with_drive(*S, "--config", "/dev/zero")),
        _opt("slam --config /dev/urandom", "/dev/urandom", _with_drive(
            *S, "--config", "/dev/urandom")),
        _opt("extract --config /dev/zero", "/dev/zero", _with_drive(
            "extract", "DRIVE", "--config", "/dev/zero", "--out", "OUT")),
        _opt("a sweep file at /dev/zero", "/dev/zero", lambda f: [
            "sweep", "/dev/zero", "--out", f / "s"]),
        _opt("a sweep file at /dev/urandom", "/dev/urandom", lambda f: [
            "sweep", "/dev/urandom", "--out", f / "s"]),
        _opt("a config of 20 MB", "big.toml", _with_drive(*S, "--config", "BIGCONF")),
        _opt("a sweep grid field nested 60 deep", "deep.toml", lambda f: [
            "sweep", _deep_sweep(f), "--out", f / "s"]),
        _opt("a sweep grid key of 5,000 dotted parts", "nested", lambda f: [
            "sweep", _sweep_with(SWEEP.replace("gate_prob = [0.9]", ".".join(["a"] * 5000)
                                               + " = [0.9]"))(f), "--out", f / "s"]),
        _opt("a configuration key of 5,000 dotted parts", "nested", _with_drive(
            *S, "--config", "DEEPCONF")),
        _opt("a scene name with a NUL byte (simulate)", "NUL", lambda f: [
            "simulate", "tree\x00park", "--pose", "0,0,0", "--out", f / "s.npz"]),
        _opt("a scene name with a NUL byte (simulate-drive)", "NUL", lambda f: [
            "simulate-drive", "tree\x00park", "--scans", "2", "--out", f / "s.npz"]),
        _opt("a sweep's scene with a NUL byte", "scene", lambda f: [
            "sweep", _sweep_with(NUL_SWEEP)(f), "--out", f / "s"]),
        _opt("an input path that is not UTF-8 (slam)", "UTF-8", lambda f: [
            "slam", _renamed(drive(f), NOT_UTF8 + ".npz"), "--out", f / "o"]),
        _opt("an --out path that is not UTF-8 (slam)", "UTF-8", _with_drive(
            "slam", "DRIVE", "--out", "NOTUTF8")),
        _opt("an --out path that is not UTF-8 (extract)", "UTF-8", _with_drive(
            "extract", "DRIVE", "--out", "NOTUTF8")),
        _opt("an --out path that is not UTF-8 (simulate-drive)", "UTF-8", lambda f: [
            "simulate-drive", "--scans", "2", "--out", f / (NOT_UTF8 + ".npz")]),
        _opt("an --out path that is not UTF-8 (export-reference)", "UTF-8", _with_drive(
            "export-reference", "DRIVE", "--out", "NOTUTF8")),
        _opt("a --config path that is not UTF-8", "UTF-8", _with_drive(
            *S, "--config", "CONFUTF8")),
        _opt("a RUN_DIR path that is not UTF-8 (smooth)", "UTF-8", lambda f: U),
        _opt("smooth --isam2-every 10**30", "isam2_every", lambda f: [
            "smooth", slam_run(f), "--solver", "isam2", "--isam2-every", BIG]),
        _opt("slam --window 10**30", "--window", _with_drive(*S, "--window", BIG)),
        _opt("slam --rerun connect=127.0.0.1:1 (nobody answers)", "127.0.0.1:1", _with_drive(
            *S, "--rerun", "connect=127.0.0.1:1")),
        _opt("slam --rerun connect=rerun+http://x:1/y (not /proxy)", "connect=rerun+http://x:1/y",
             _with_drive(*S, "--rerun", "connect=rerun+http://x:1/y")),
        _opt("slam --rerun connect=h:99999 (port out of range)", "connect=h:99999", _with_drive(
            *S, "--rerun", "connect=h:99999")),
        _opt("extract --rerun connect=ftp://h:1/proxy (scheme)", "ftp", _with_drive(
            "extract", "DRIVE", "--out", "OUT", "--rerun", "connect=ftp://h:1/proxy")),
        _opt("extract --rerun connect= (no address)", "no address", _with_drive(
            "extract", "DRIVE", "--out", "OUT", "--rerun", "connect=")),
        _opt("slam --ellipse-scale nan", "--ellipse-scale", _with_drive(
            *S, "--ellipse-scale", "nan")),
        _opt("slam --initial-heading inf", "initial", _with_drive(
            *S, "--initial-heading", "inf")),
        _opt("slam --initial-heading 1e300 (a run from its truth: ignored)", "", _with_drive(
            *S, "--initial-heading", "1e300"), ok_if_runs=True),
        _opt("simulate --seed 10**30", "--seed", lambda f: [
            "simulate", "test_yard", "--pose", "0,0,0", "--seed", BIG, "--out", f / "s.npz"],
             ok_if_runs=True),
        _opt("simulate-drive --seed 10**30", "--seed", lambda f: [
            "simulate-drive", "--scans", "2", "--seed", BIG, "--out", f / "s.npz"],
             ok_if_runs=True),
        _opt("simulate-drive --scans 10**30", "n_scans", lambda f: [
            "simulate-drive", "--scans", BIG, "--out", f / "s.npz"]),
        _opt("simulate --noise nan", "--noise", lambda f: [
            "simulate", "test_yard", "--pose", "0,0,0", "--noise", "nan", "--out", f / "s.npz"]),
        _opt("simulate --pose 1e300,0,0", "pose", lambda f: [
            "simulate", "test_yard", "--pose", "1e300,0,0", "--out", f / "s.npz"]),
        _opt("reproduce --seed 10**30", "--seed", lambda f: [
            "reproduce", "noise-calibration", "--quick", "--seed", BIG, "--workers", "1",
            "--out", f / "r"], ok_if_runs=True),
        _opt("bench association --seed 10**30", "--seed", lambda f: [
            "bench", "association", "--repeats", "1", "--seed", BIG], ok_if_runs=True),
    ]  # fmt: skip


def _renamed(p: Path, name: str) -> Path:
    return p.rename(p.with_name(name))


def _expand(case: CommandCase) -> CommandCase:
    """Placeholders made at build time: BIGCONF (a 20 MB configuration), NOTUTF8 (a path
    whose bytes are not UTF-8), CONFUTF8 (a configuration at such a path)."""

    def build(folder: Path):
        args, protected = case.build(folder)
        out = []
        for a in args:
            if a == "BIGCONF":
                a = folder / "big.toml"
                a.write_text("# padding\n" * 2_000_000)
            elif a == "NOTUTF8":
                a = folder / NOT_UTF8
            elif a == "DEEPCONF":
                a = folder / "deep.toml"
                a.write_text("[features]\n" + ".".join(["a"] * 5000) + " = 1\n")
            elif a == "RUNUTF8":
                a = slam_run(folder).rename(folder / NOT_UTF8)
            elif a == "CONFUTF8":
                a = folder / (NOT_UTF8 + ".toml")
                a.write_text("")
            out.append(a)
        return out, protected

    return CommandCase(case.kind, case.label, case.key, build, case.ok_if_runs)


# ---- kind "closure" -----------------------------------------------------------------------------

LOOP_STEP, LOOP_SCANS = 3, 1100  # every 3rd scan of the first 1100: the return is at 955
GPS_STEP = 5  # every 5th fix: 2 Hz instead of 10 (see _loop_files)


@functools.cache
def _loop_files() -> tuple[bytes, dict]:
    """(a loop drive's sequence file, the loop-closure experiment's configuration as a
    table): the simulated park loop of `trunkslam reproduce loop-closure` (seed 0), every 3rd
    scan of its first 1100 so that a run takes seconds; loop closure is tried on it and
    accepts a match (at the return). Its GPS at 2 Hz (every 5th fix of 10 Hz), still about 40
    fixes in each +-10 s window the vouched-fix rule reads, so the run's GPS scores are still
    computed: the closure settings never reach that rule (it reads the vehicle's odometry and
    the fixes, no SLAM output), and at 10 Hz it took 80 % of each run (5.7 of 7.1 s)."""
    from experiments.io.sequence_file import save_sequence
    from experiments.paper.loop_closure import NOISE_SCALE, loop_config
    from experiments.sim.loops import loop_drive

    seq = loop_drive(0, "park", NOISE_SCALE)
    with tempfile.TemporaryDirectory() as d:
        with np.load(save_sequence(seq, Path(d) / "loop.npz")) as z:
            arrays = {k: z[k] for k in z.files}
        n = arrays["scan_t"].shape[0]
        for k, v in arrays.items():
            if (k.startswith("scan_") or k.startswith("truth_")) and v.ndim and v.shape[0] == n:
                arrays[k] = v[:LOOP_SCANS:LOOP_STEP]
        t_end = float(arrays["scan_t"][-1]) + 1.0
        for part in ("odo", "gps", "truth"):
            keep = arrays[f"{part}_t"] <= t_end
            if part == "gps":
                keep &= np.arange(keep.size) % GPS_STEP == 0
            for k, v in arrays.items():
                if k.startswith(part + "_") and v.ndim and v.shape[0] == keep.size:
                    arrays[k] = v[keep]
        np.savez(Path(d) / "cut.npz", **arrays)
        return (Path(d) / "cut.npz").read_bytes(), loop_config(True).to_dict()


OUTSIDE = {"0": 0, "-1": -1, "inf": math.inf, "NaN": math.nan}  # refused by every number field
INSIDE_FLOAT = {"5e-324": 5e-324, "1e300": 1e300}  # positive, finite
INSIDE_INT = {"10**18": 10**18}


def _closure_case(name: str, shown: str, value, inside: bool) -> CommandCase:
    def build(folder: Path):
        import tomli_w

        data, config = _loop_files()
        config = config | {"closure": config["closure"] | {name: value}}
        cfg = folder / "closure.toml"
        cfg.write_text(tomli_w.dumps(config))
        d = folder / "loop.npz"
        d.write_bytes(data)
        return ["slam", d, "--config", cfg, "--out", folder / "out"], [d, cfg]

    return CommandCase("closure", f"closure.{name} = {shown}", name, build, ok_if_runs=inside)


def closure_cases() -> list[CommandCase]:
    from slam import SlamConfig

    out = []
    for name, default in SlamConfig().to_dict()["closure"].items():
        if isinstance(default, bool):
            out.append(_closure_case(name, "1 (a number)", 1, False))
            out.append(_closure_case(name, str(not default).lower(), not default, True))
            continue
        for shown, v in OUTSIDE.items():
            out.append(_closure_case(name, shown, v, name == "tree_sd_m" and v == 0))  # (>= 0)
        inside = INSIDE_INT if isinstance(default, int) else INSIDE_FLOAT
        for shown, v in inside.items():
            out.append(_closure_case(name, shown, v, name != "match_m" or v >= 1e-3))
    out.append(_closure_case("jc_prob", "1.0", 1.0, False))
    out.append(_closure_case("jc_prob", "1 - 1e-16", 1 - 1e-16, True))
    out.append(_closure_case("recent_s", "100 (above old_s)", 100.0, False))
    out.append(_closure_case("match_m", "1e-3 (its least)", 1e-3, True))
    out.append(_closure_case("min_pairs", "2", 2, False))
    return out


# ---- the audit ----------------------------------------------------------------------------------


def command_cases(kind: str) -> list[CommandCase]:
    return {
        "rosbag": rosbag_cases,
        "links": links_cases,
        "options": option_cases,
        "closure": closure_cases,
    }[kind]()


VERDICTS = ("clear", "ran", "unclear", "accepted", "traceback")


def audit(kinds=KINDS, show: int = 0) -> dict[str, dict[str, int]]:
    """{kind: {verdict: count}} over the case lists; prints `show` examples of each failure."""
    counts = {}
    with tempfile.TemporaryDirectory() as d:
        for kind in kinds:
            c = {"cases": 0, **dict.fromkeys(VERDICTS, 0)}
            for i, case in enumerate(command_cases(kind)):
                v, detail = command_verdict(case, Path(d) / f"{kind}{i}")
                c["cases"] += 1
                c[v] += 1
                if v not in ("clear", "ran") and c[v] <= show:
                    print(f"  {v}: {case!r}: {_flat(detail)[-300:]}", file=sys.stderr)
            counts[kind] = c
            print(kind, c, file=sys.stderr)
    return counts


if __name__ == "__main__":
    # the project before tests/ (whose slam/ and features/ test folders would shadow ours)
    here = Path(__file__).resolve().parent
    sys.path[:] = [str(here.parent), str(here)] + [p for p in sys.path if p not in ("", str(here))]
    import json

    print(json.dumps(audit(show=int(sys.argv[1]) if len(sys.argv) > 1 else 0), indent=1))

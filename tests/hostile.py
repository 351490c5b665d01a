"""Hostile files (issue 29): a valid file of every format trunkslam reads, the ways a file can
be wrong, and the verdict of the format's reader on each.

Formats: the sequence file (`.npz`), the run log (`run_log.npz`, what `trunkslam smooth`
reads), the features JSON (`trunkslam slam --features-file`), the SLAM configuration (TOML), the
sweep specification (TOML) and the scene file (JSON).

- `cases(fmt)`: the audit's case list, deterministic. Each case writes one file that is wrong
  for certain (a table where a number belongs, a complex array, a NaN pose, a missing required
  key, an unknown key, an encrypted archive member, ...) and names the key the error must name.
- `verdict(case, folder)`: what the reader does with it: "clear" (the project's error, naming
  the file and the key), "unclear" (the project's error without them), "accepted" (no error: a
  silent acceptance, or for a sweep a late validation: the trials would meet it),
  "traceback" (another exception).
- Hypothesis strategies for the fuzz tests (`mutated_tree`, `mutated_arrays`): a valid file's
  parsed structure mutated (types, shapes, NaN/inf, huge values, missing and extra keys,
  nesting) and written back.

Run as a script it prints the audit's counts per format and verdict:
`python tests/hostile.py` (the counts in docs/outputs.md, checked by test_hostile_files.py),
then those of the whole commands' case kinds (`tests/hostile_commands.py`: convert rosbag,
links, option extremes, the [closure] section; checked by test_hostile_commands.py).
"""

from __future__ import annotations

import copy
import functools
import io
import json
import math
import os
import sys
import tempfile
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FORMATS = ("sequence", "run_log", "features", "config", "sweep", "scene")

# ---- the valid files --------------------------------------------------------------------------


@functools.cache
def base_sequences() -> dict[str, dict[str, np.ndarray]]:
    """The arrays of valid sequence files: a simulated car drive (5 scans: scans, odometry,
    vehicle, GPS, truth, labels), the unit tests' run with every field (detections too), and a
    unicycle's and a pose-increment robot's."""
    from support import full_kwargs

    from experiments.io.sequence_file import save_sequence
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import Sequence

    out = {}
    drive = simulate_cycab_run(np.random.default_rng(0), "tree_park", CycabParams(n_scans=5))
    kw = full_kwargs()
    m = kw["odo_t"].size
    robots = {
        "unicycle": kw | {"vehicle": {"model": "unicycle"}, "odo_steer": None,
                          "odo_yaw_rate": np.linspace(-0.3, 0.3, m)},
        "pose_increment": kw | {"vehicle": {"model": "pose-increment"}, "odo_steer": None,
                                "odo_speed": None,
                                "odo_pose": np.column_stack([np.arange(m) * 0.1, np.zeros(m),
                                                             np.linspace(0, 1, m)])},
    }  # fmt: skip
    seqs = {"drive": drive, "full": Sequence(**kw)}
    seqs |= {k: Sequence(**v) for k, v in robots.items()}
    with tempfile.TemporaryDirectory() as d:
        for name, seq in seqs.items():
            p = save_sequence(seq, Path(d) / f"{name}.npz")
            with np.load(p) as z:
                out[name] = {k: z[k] for k in z.files}
    return out


@functools.cache
def base_run_log() -> dict[str, np.ndarray]:
    """The arrays of the run log of an 8-scan simulated drive."""
    from experiments.io.run_log import write_run_log
    from experiments.sim import CycabParams, simulate_cycab_run
    from slam import run_slam

    seq = simulate_cycab_run(np.random.default_rng(3), "tree_park", CycabParams(n_scans=8))
    lg = run_slam(seq)
    with tempfile.TemporaryDirectory() as d:
        p = write_run_log(Path(d) / "run_log.npz", lg)
        with np.load(p) as z:
            return {k: z[k] for k in z.files}


FEATURES_SCANS = 3


@functools.cache
def base_features() -> tuple[dict, int]:
    """(a features JSON document of 3 scans with circles, lines, edges and clutter, its beams)."""
    from experiments.io.writers import FEATURES_SCHEMA, features_to_dict
    from experiments.sim import CycabParams, simulate_cycab_run
    from features import extract_features

    seq = simulate_cycab_run(
        np.random.default_rng(0), "tree_park", CycabParams(n_scans=FEATURES_SCANS)
    )
    scans = [
        features_to_dict(extract_features(seq.scan(k), "paper"), k) for k in range(seq.n_scans)
    ]
    doc = {"schema": FEATURES_SCHEMA, "input": "run.npz", "method": "paper",
           "params": {"sigma_r_m": 0.02}, "frame": "laser", "scans": scans}  # fmt: skip
    return json.loads(json.dumps(doc)), seq.n_beams


@functools.cache
def base_config() -> dict:
    """Every setting of a configuration, the optional ones given too."""
    from slam import SlamConfig

    d = SlamConfig().to_dict()
    d["features"]["file"] = "features.json"
    d["vehicle"]["laser_pose"] = [1.5, 0.0, 0.0]
    d["vehicle"]["gps_antenna"] = [1.5, 0.0]
    d["start"]["initial_heading_rad"] = 0.5
    d["association"]["params"] = {"p_detect": 0.9}
    return d


@functools.cache
def base_sweeps() -> dict[str, dict]:
    """A sweep file of each study: a grid of two values of one field, every other field set in
    [base] to its default (so that each can be made wrong)."""
    from experiments.paper.sweep import study_defaults

    grid = {"association": ("gate_prob", [0.9, 0.99]), "slam": ("cycab.range_sigma_m",
            [0.01, 0.02]), "circles": ("noise_m", [0.01, 0.02])}  # fmt: skip
    out = {}
    for study, (field, values) in grid.items():
        base = {k: v for k, v in study_defaults(study).items() if v is not None and k != field}
        out[study] = {"study": study, "trials": 2, "seed": 0, "base": base,
                      "grid": {field: values}, "executor": {"workers": 1}}  # fmt: skip
    return out


@functools.cache
def base_scene() -> dict:
    """The bundled test yard, cut to two trees, a wall, a bush and two scan positions."""
    from experiments.bundled import scenes_dir

    d = json.loads((scenes_dir() / "test_yard.json").read_text())
    d["circles"], d["walls"], d["bushes"] = d["circles"][:2], d["walls"][:1], d["bushes"][:1]
    d["scan_positions"], d["scan_position_names"] = (
        d["scan_positions"][:2],
        d["scan_position_names"][:2],
    )
    d["description"] = "the test yard, cut down"
    d["trunk_shape"] = {"aspect": 1.2, "lobes": 3, "lobe_amplitude": 0.05, "seed": 1}
    return d


# ---- writing files ----------------------------------------------------------------------------


def npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=True)
    return buf.getvalue()


def write_npz(path: Path, arrays: dict, raw: dict | None = None) -> Path:
    """An .npz of `arrays`; `raw` maps names to member bytes written as they are."""
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in arrays.items():
            zf.writestr(f"{k}.npy", (raw or {}).get(k) or npy_bytes(v))
    return path


def write_json(path: Path, obj) -> Path:
    path.write_text(json.dumps(obj))  # NaN and inf as the (non-standard) tokens
    return path


def write_toml(path: Path, obj) -> Path:
    import tomli_w

    path.write_text(tomli_w.dumps(obj))
    return path


def encrypt_first_member(path: Path) -> Path:
    """Set the "encrypted" flag of the archive's first member (its local and central headers)."""
    data = bytearray(path.read_bytes())
    data[6] |= 1  # local file header: general purpose flags at offset 6
    cd = data.find(b"PK\x01\x02")
    data[cd + 8] |= 1  # central directory header: flags at offset 8
    path.write_bytes(bytes(data))
    return path


# ---- the readers ------------------------------------------------------------------------------


def read(fmt: str, path: Path):
    """The format's reader on `path`: the object it makes."""
    if fmt == "sequence":
        from experiments.io.sequence_file import load_sequence

        return load_sequence(path)
    if fmt == "run_log":
        from experiments.io.run_log import read_run_log

        return read_run_log(path, "all")
    if fmt == "features":
        from experiments.io.features_json import load_features_json

        return load_features_json(path, FEATURES_SCANS, base_features()[1])
    if fmt == "config":
        from experiments.io.config_file import load_slam_config

        return load_slam_config(path)
    if fmt == "sweep":
        from experiments.paper.sweep import load_sweep

        return load_sweep(path)
    if fmt == "scene":
        from experiments.sim.scene import load_scene

        return load_scene(path)
    raise ValueError(fmt)


def project_errors() -> tuple[type[BaseException], ...]:
    """The project's own errors (every one a ValueError)."""
    from association.errors import AssociationError
    from experiments.errors import TrunkslamError
    from features.errors import FeaturesError
    from slam.errors import SlamError

    return (TrunkslamError, FeaturesError, AssociationError, SlamError)


# ---- the cases --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One hostile file: its format, a label, the key its error must name, and how to write it
    (build(folder) -> the file's path)."""

    fmt: str
    label: str
    key: str
    build: Callable[[Path], Path]

    def __repr__(self) -> str:
        return f"{self.fmt}: {self.label}"


def verdict(case: Case, folder: Path) -> tuple[str, str]:
    """(verdict, detail): "clear", "unclear", "accepted" or "traceback"; see the module doc."""
    folder.mkdir(parents=True, exist_ok=True)
    path = case.build(folder)
    try:
        read(case.fmt, path)
    except project_errors() as exc:
        msg = str(exc)
        if str(path) in msg and case.key in msg:
            return "clear", msg
        return "unclear", msg
    except RecursionError as exc:  # not an Exception subclass issue: report it as it is
        return "traceback", repr(exc)
    except Exception as exc:
        return "traceback", f"{type(exc).__name__}: {exc}"[:300]
    return "accepted", ""


# tree mutations: (name, the new value from the old one or None when it does not apply)
DEEP = functools.reduce(lambda v, _: [v], range(50), 1.0)
HUGE = 10**400
TREE_MUTATIONS: dict[str, Callable] = {
    "a table": lambda v: None if isinstance(v, dict) else {"bogus_key": 1},
    "a mixed list": lambda v: [[1], {"a": 2}, "x"],
    "a string": lambda v: None if isinstance(v, str) else "bogus",
    "a boolean": lambda v: None if isinstance(v, bool) else True,
    "a 400-digit integer": lambda v: HUGE,
    "NaN": lambda v: math.nan,
    "nested 50 deep": lambda v: DEEP,
}


def tree_paths(obj, prefix=()):
    """Key paths of every node under obj (lists: their first and last items)."""
    if isinstance(obj, dict):
        items = obj.items()
    elif isinstance(obj, list):
        items = [(i, obj[i]) for i in sorted({0, len(obj) - 1})] if obj else []
    else:
        return
    for k, v in items:
        yield (*prefix, k)
        yield from tree_paths(v, (*prefix, k))


def get_at(obj, path):
    for k in path:
        obj = obj[k]
    return obj


def set_at(obj, path, value):
    get_at(obj, path[:-1])[path[-1]] = value


def leaf_key(path) -> str:
    """The last named key of a path (what an error about it names); of a dotted field name
    ("cycab.sensor", a sweep's), its last part."""
    key = next((str(k) for k in reversed(path) if isinstance(k, str)), "")
    return key.rsplit(".", 1)[-1]


def dotted(path) -> str:
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


def tree_cases(fmt: str, base, write, tolerated, label_prefix="", json_null=False) -> list[Case]:
    """Every tree mutation at every key path of `base` (one at a time), the removal of every key
    and an unknown key in every table; without the ones `tolerated(path, mutation)` says are
    valid files."""
    out = []
    mutations = dict(TREE_MUTATIONS)
    if json_null:
        mutations["null"] = lambda v: None if v is None else None
    for path in tree_paths(base):
        old = get_at(base, path)
        for name, make in mutations.items():
            new = make(old)
            if (new is None and name != "null") or tolerated(path, name):
                continue
            out.append(_tree_case(fmt, base, write, path, name, new, label_prefix))
        if isinstance(path[-1], str) and not tolerated(path, "removed"):
            out.append(_tree_case(fmt, base, write, path, "removed", _REMOVE, label_prefix))
    for path in [(), *tree_paths(base)]:
        if isinstance(get_at(base, path), dict) and not tolerated((*path, "bogus_key"), "unknown"):
            out.append(
                _tree_case(fmt, base, write, (*path, "bogus_key"), "unknown", 1, label_prefix)
            )
    return out


_REMOVE = object()


def _tree_case(fmt, base, write, path, name, new, prefix) -> Case:
    def build(folder: Path) -> Path:
        obj = copy.deepcopy(base)
        if new is _REMOVE:
            del get_at(obj, path[:-1])[path[-1]]
        else:
            set_at(obj, path, new)
        return write(folder, obj)

    where = dotted(path)
    label = f"{prefix}{where}: {'removed' if new is _REMOVE else name}"
    key = leaf_key(path)
    if new is _REMOVE and len(get_at(base, path[:-1])) == 1:
        key = leaf_key(path[:-1])  # the table is left empty: that is what is wrong
    return Case(fmt, label, key, build)


# ---- sequence and run log: array mutations ------------------------------------------------------


def _with(a: np.ndarray, value) -> np.ndarray:
    b = a.astype(np.float64).copy()
    b.reshape(-1)[b.size // 2] = value
    return b


ARRAY_MUTATIONS: dict[str, Callable[[np.ndarray], np.ndarray | None]] = {
    "complex": lambda a: a.astype(np.complex128) + 1j if a.dtype.kind in "fiu" else None,
    "datetime64": lambda a: np.zeros(a.shape, "datetime64[s]") if a.dtype.kind in "fiu" else None,
    "boolean": lambda a: np.ones(a.shape, bool),
    "strings": lambda a: np.full(a.shape or (2,), "1.5"),
    "bytes": lambda a: np.full(a.shape or (), b"1.5"),
    "objects": lambda a: np.array([None, 1.5], dtype=object),
    "0-d": lambda a: np.array(a.reshape(-1)[0]) if a.ndim else None,
    "2 values for one": lambda a: None if a.ndim else np.array([a, a]),
    "an extra dimension": lambda a: a[..., None].repeat(2, -1) if a.ndim else None,
    "a row short": lambda a: a[:-1] if a.ndim and a.shape[0] > 1 else None,
    "NaN": lambda a: _with(a, math.nan) if a.dtype.kind in "fiu" and a.size else None,
    "inf": lambda a: _with(a, math.inf) if a.dtype.kind in "fiu" and a.size else None,
    "1e300": lambda a: _with(a, 1e300) if a.dtype.kind == "f" and a.size else None,
    "2**62": lambda a: a + 2**62 if a.dtype.kind == "i" and a.size else None,
    "reversed": lambda a: a[::-1] if a.ndim == 1 and a.size > 1 else None,
    "float32": lambda a: None,  # written by other tools: valid (listed for the fuzz only)
}
STRING_MUTATIONS: dict[str, Callable] = {
    "a number": lambda s: np.array(3.0),
    "an empty string": lambda s: np.array(""),
    "a list of strings": lambda s: np.array([str(s), str(s)]),
    "bytes": lambda s: np.array(str(s).encode()),
    "a number as text": lambda s: np.array("3.0"),
}


def npz_cases(fmt: str, arrays: dict, tolerated, label_prefix: str = "") -> list[Case]:
    """Every array mutation of every variable, every variable removed, and the file-level
    damage (trailing bytes in a member, truncation, an encrypted member, ...)."""
    out = []

    def case(label, key, make_arrays=None, raw=None, after=None):
        def build(folder: Path) -> Path:
            p = write_npz(folder / "hostile.npz", make_arrays() if make_arrays else arrays, raw)
            return after(p) if after else p

        out.append(Case(fmt, f"{label_prefix}{label}", key, build))

    for k, a in arrays.items():
        muts = STRING_MUTATIONS if a.dtype.kind == "U" else ARRAY_MUTATIONS
        for name, make in muts.items():
            if tolerated(k, name):
                continue
            new = make(a)
            if new is None:
                continue
            case(f"{k}: {name}", k, lambda k=k, new=new: {**arrays, k: new})
        if not tolerated(k, "removed"):
            case(f"{k}: removed", k, lambda k=k: {j: v for j, v in arrays.items() if j != k})
        if not tolerated(k, "trailing bytes"):
            case(f"{k}: 16 bytes after its data", k, raw={k: npy_bytes(a) + b"\0" * 16})
        if a.dtype.kind == "f" and a.size and not tolerated(k, "truncated"):
            case(f"{k}: its data cut short", k, raw={k: npy_bytes(a)[:-8]})
    return out


def _parses(suffix: str, data: bytes) -> bool:
    """Whether `data` is a valid TOML (".toml") or JSON (".json") document."""
    import tomllib

    try:
        text = data.decode("utf-8")
        tomllib.loads(text) if suffix == ".toml" else json.loads(text)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, json.JSONDecodeError):
        return False
    return True


def file_cases(fmt: str, good: Callable[[Path], Path]) -> list[Case]:
    """Damage to the file as a whole: the key to name is the file's own name."""

    def damaged(label, change):
        def build(folder: Path) -> Path:
            return change(good(folder))

        return Case(fmt, f"file: {label}", "", build)

    def truncate(p):
        b = p.read_bytes()
        n = len(b) // 2
        if p.suffix in (".toml", ".json"):
            # a cut can leave a shorter valid file (a TOML prefix that sets fewer keys, a
            # number cut short): cut further on, byte by byte, until the prefix no longer parses
            while n < len(b) and _parses(p.suffix, b[:n]):
                n += 1
        p.write_bytes(b[:n])
        return p

    def empty(p):
        p.write_bytes(b"")
        return p

    def junk(p):
        p.write_bytes(bytes(range(256)) * 4)
        return p

    def loop(p):
        p.unlink()
        p.symlink_to(p.name)  # a link to itself
        return p

    def folder(p):
        p.unlink()
        p.mkdir()
        return p

    def not_utf8(p):
        p.write_bytes(b"\xff\xfe" + p.read_bytes())
        return p

    def unreadable(p):
        os.chmod(p, 0)
        return p

    out = [
        damaged("cut in half", truncate),
        damaged("empty", empty),
        damaged("binary junk", junk),
        damaged("a symbolic link to itself", loop),
        damaged("a folder", folder),
    ]
    if os.geteuid() != 0:  # root reads any file
        out.append(damaged("no read permission", unreadable))
    if fmt in ("sequence", "run_log"):
        out.append(damaged("an encrypted member", encrypt_first_member))

        def trailing(p):
            p.write_bytes(p.read_bytes() + b"trailing garbage")
            return p

        out.append(damaged("bytes after the archive", trailing))
    else:
        out.append(damaged("not UTF-8", not_utf8))
    return out


# Valid files among the mutations (the format allows them): each with its reason.
SEQUENCE_VALID = {
    # NaN is no return, inf and huge readings are beyond any range (datasets/FORMAT.md)
    ("scan_ranges", "NaN"), ("scan_ranges", "inf"), ("scan_ranges", "1e300"),
    ("det_radius", "NaN"),  # a detector that gives no radius
    ("scan_max_range", "inf"), ("scan_max_range", "1e300"),  # no limit
    ("scan_labels", "2**62"),  # objects other than landmarks have labels >= L
    # optional variables, absent: not known
    *[(k, "removed") for k in ("scan_max_range", "name", "gps_pose", "truth_landmarks",
                                "scan_labels", "det_cov", "det_method", "vehicle",
                                "scan_n_beams", "gps_origin")],
    ("name", "an empty string"), ("name", "a number as text"),  # free text
    ("truth_landmarks", "a row short"),  # any number of landmarks
    ("det_scan", "reversed"),  # the drive's: all in order
}  # fmt: skip


def sequence_cases() -> list[Case]:
    out = []
    seqs = base_sequences()
    for name, arrays in seqs.items():
        keys = set(arrays) if name in ("drive", "full") else {"odo_yaw_rate", "odo_pose"}
        sub = {k: v for k, v in arrays.items()}

        def tolerated(k, mutation, keys=keys, arrays=arrays):
            if k not in keys:
                return True
            if (k, mutation) in SEQUENCE_VALID:
                return True
            if mutation == "reversed" and not k.endswith("_t") and k != "det_scan":
                return True  # other values reversed are other valid values
            if k == "det_scan" and mutation == "reversed":
                return np.all(np.diff(arrays[k]) == 0)
            return False

        out += npz_cases("sequence", sub, tolerated, f"{name} ")
    # the vehicle's JSON object
    vehicle = json.loads(str(seqs["full"]["vehicle"]))

    def write_vehicle(folder: Path, obj) -> Path:
        return write_npz(folder / "hostile.npz", {**seqs["full"], "vehicle": np.array(
            json.dumps(obj))})  # fmt: skip

    def vehicle_tolerated(path, mutation):
        return path == ("encoder_offset_m",) and mutation == "removed"  # defaults to 0

    out += tree_cases("sequence", vehicle, write_vehicle, vehicle_tolerated, "vehicle.", True)
    out += file_cases("sequence", lambda f: write_npz(f / "hostile.npz", seqs["drive"]))
    return out


RUN_LOG_VALID = {
    ("features", "removed"), ("association", "removed"),  # names only, for the summary
}  # fmt: skip


def run_log_cases() -> list[Case]:
    arrays = base_run_log()

    def tolerated(k, mutation):
        if (k, mutation) in RUN_LOG_VALID:
            return True
        # row 0 of odo_delta, odo_cov is unused (zeros): reversing moves a real row there
        return mutation == "reversed" and k not in ("scan_t", "meas_scan")

    out = npz_cases("run_log", arrays, tolerated)
    out += file_cases("run_log", lambda f: write_npz(f / "hostile.npz", arrays))
    return out


def features_cases() -> list[Case]:
    doc, _ = base_features()
    free = {"input", "frame"}  # free text: any string

    def tolerated(path, mutation):
        key = leaf_key(path)
        if path and path[0] == "params":
            return True  # what the extractor was given, kept for the record, not read
        if mutation == "a string" and key in free:
            return True
        if mutation == "null" and key in (
            "stamp_s",
            "radius_m",
            "cov",
            "rms_residual_m",
            "alpha_rad",
            "rho_m",
            "endpoints_xy",
            "point_xy",
        ):
            return isinstance(path[-1], int) or key in (
                "stamp_s",
                "radius_m",
                "rms_residual_m",
                "alpha_rad",
                "rho_m",
            )
        if mutation == "removed" and key in free | {
            "params",
            "frame",
            "rms_residual_m",
            "stamp_s",
            "method",
            "lines",
            "edges",
            "clutter",
        }:
            return len(path) > 1 or key != "method"  # the file's method names the noise model
        return False

    def write(folder, obj):
        return write_json(folder / "hostile.json", obj)

    out = tree_cases("features", doc, write, tolerated, json_null=True)
    out += file_cases("features", lambda f: write_json(f / "hostile.json", doc))
    return out


def config_cases() -> list[Case]:
    base = base_config()

    def tolerated(path, mutation):
        key = leaf_key(path)
        if mutation == "removed":
            return True  # every setting has a default
        if path[:2] == ("association", "params") and len(path) == 2:
            return mutation == "a table"  # free-form, checked against the method
        if mutation == "a string" and key == "file":
            return True  # a path
        if mutation == "a boolean" and key in ("first_estimates_jacobians",):
            return True
        return False

    def write(folder, obj):
        return write_toml(folder / "hostile.toml", obj)

    out = tree_cases("config", base, write, tolerated)
    out += [c for c in file_cases("config", lambda f: write_toml(f / "hostile.toml", base))
            if c.label != "file: empty"]  # an empty configuration: every default  # fmt: skip
    return out


def sweep_cases() -> list[Case]:
    out = []
    for study, doc in base_sweeps().items():

        def tolerated(path, mutation, study=study):
            if path[0] == "base" and len(path) <= 2 and mutation == "removed":
                return True  # the field's default (every field's, without [base])
            if path[0] in ("seed", "executor") and mutation == "removed":
                return True  # seed 0, the executor of the command line
            if path == ("trials",) and mutation == "removed":
                return True  # 10
            if path == ("seed",) and mutation == "a 400-digit integer":
                return True  # any whole number >= 0 seeds numpy
            if path[0] == "base" and len(path) >= 2:
                return _sweep_value_ok(study, path[1], mutation)
            return False

        def write(folder, obj):
            return write_toml(folder / "hostile.toml", obj)

        # values: every field of the study (in [base]); the structure: the file's own keys
        out += tree_cases("sweep", doc, write, tolerated, f"{study} ")
    out += file_cases("sweep", lambda f: write_toml(f / "hostile.toml", base_sweeps()["circles"]))
    return out


def _sweep_value_ok(study: str, field: str, mutation: str) -> bool:
    """Whether `mutation` of the study's `field` is a valid value of it."""
    from experiments.paper.sweep import study_defaults

    fields = study_defaults(study)
    if field not in fields:
        return False  # an unknown field
    default = fields[field]
    if mutation == "a boolean":
        return isinstance(default, bool)
    if mutation == "a string":
        return field.endswith(".file")
    if mutation == "a mixed list" or mutation == "a table":
        return False
    return False


def scene_cases() -> list[Case]:
    base = base_scene()
    free = {"description", "frame", "note", "notes", "name"}

    def tolerated(path, mutation):
        key = leaf_key(path)
        if key in free and mutation in ("a string", "removed"):
            return True
        if path[0] == "scan_position_names" and mutation == "a string":
            return True
        if mutation == "removed" and key in (
            "kind",
            "height_m",
            "closed",
            "schema",
            "scan_positions",
            "scan_position_names",
            "walls",
            "bushes",
            "circles",
            "trunk_shape",
            "aspect",
            "lobe_amplitude",
            "seed",
        ):
            return True  # defaults
        if path == ("description",) and mutation == "a mixed list":
            return False
        if path[0] == "description" and len(path) == 2:
            return mutation == "a string"
        return False

    def write(folder, obj):
        return write_json(folder / "hostile.json", obj)

    out = tree_cases("scene", base, write, tolerated, json_null=True)
    out += file_cases("scene", lambda f: write_json(f / "hostile.json", base))
    return out


def cases(fmt: str) -> list[Case]:
    return {
        "sequence": sequence_cases,
        "run_log": run_log_cases,
        "features": features_cases,
        "config": config_cases,
        "sweep": sweep_cases,
        "scene": scene_cases,
    }[fmt]()


# ---- the audit ---------------------------------------------------------------------------------


def audit(formats=FORMATS, show: int = 0) -> dict[str, dict[str, int]]:
    """{format: {verdict: count}} over the case list; prints `show` examples of each failure."""
    counts = {}
    with tempfile.TemporaryDirectory() as d:
        for fmt in formats:
            c = {"cases": 0, "clear": 0, "unclear": 0, "accepted": 0, "traceback": 0}
            for i, case in enumerate(cases(fmt)):
                v, detail = verdict(case, Path(d) / f"{fmt}{i}")
                c["cases"] += 1
                c[v] += 1
                if v != "clear" and c[v] <= show:
                    print(f"  {v}: {case!r}: {detail[:200]}", file=sys.stderr)
            counts[fmt] = c
            print(fmt, c, file=sys.stderr)
    return counts


if __name__ == "__main__":
    # the project before tests/ (whose slam/ and features/ test folders would shadow ours),
    # tests/ for its support module
    here = Path(__file__).resolve().parent
    sys.path[:] = [str(here.parent), str(here)] + [p for p in sys.path if p not in ("", str(here))]
    shown = int(sys.argv[1]) if len(sys.argv) > 1 else 0
    total = audit(show=shown)
    from hostile_commands import audit as command_audit  # whole commands (issue 43)

    total |= command_audit(show=shown)
    print(json.dumps(total, indent=1))


# ---- hypothesis: mutations of valid files -------------------------------------------------------


def _strategies():
    """The hypothesis strategies (imported lazily: the audit script runs without hypothesis)."""
    from hypothesis import strategies as st

    special_floats = st.sampled_from(
        [math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, 0.0, -0.0, -1.0, 1e-300]
    )
    special_ints = st.sampled_from([10**400, -(10**400), 2**63, 2**64, -(2**63) - 1, 0, -1])
    words = st.sampled_from(
        ["", " ", "bogus", "nan", "inf", "paper", "bailey", "ihgr", "hough", "tree_park",
         "laser", "ackermann", "trunkslam.features/1", "trunkslam-scene/1", "\x00", "é"]
    )  # fmt: skip

    def leaves(none: bool):
        base = st.one_of(
            st.booleans(),
            st.integers(min_value=-(2**70), max_value=2**70),
            special_ints,
            st.floats(allow_nan=True, allow_infinity=True),
            special_floats,
            st.text(max_size=6),
            words,
        )
        return st.one_of(st.none(), base) if none else base

    @functools.cache  # one strategy each, built once: not again at every draw of a mutation
    def values(none: bool):
        return st.recursive(
            leaves(none),
            lambda c: (
                st.lists(c, max_size=4)
                | st.dictionaries(st.text(max_size=5) | words, c, max_size=3)
            ),
            max_leaves=6,
        )

    return st, values, special_floats, special_ints


def _items(obj):
    """An iterator over (key, value) of a table or (index, item) of a list; None for a leaf."""
    if isinstance(obj, dict):
        return iter(list(obj.items()))
    if isinstance(obj, list):
        return iter(list(enumerate(obj)))
    return None


def all_paths(obj, prefix=()):
    """Every key path under obj (every list item), each before the paths under it, in the
    document's order. A stack, not nested generators: a value nested 400 deep (the `deep`
    mutation) costs 400 steps, not a yield through each level for each path below it."""
    stack = [(_items(obj), prefix)] if _items(obj) is not None else []
    while stack:
        items, above = stack[-1]
        for k, v in items:
            path = (*above, k)
            yield path
            below = _items(v)
            if below is not None:
                stack.append((below, path))
                break
        else:
            stack.pop()


def mutated_tree(base, *, none: bool = True, max_ops: int = 3):
    """A strategy: `base` (a parsed JSON or TOML document) with 1..max_ops mutations: a node
    replaced by a hostile value (any type, NaN/inf, huge or tiny numbers, strings, nested lists
    and tables), removed, wrapped in a list or table, nested deep, replaced by another node's
    value (a valid value in the wrong place), a key added, a list item duplicated or dropped, a
    number nudged. none: whether null is a value (JSON yes, TOML no)."""
    st, values, special_floats, special_ints = _strategies()

    @st.composite
    def strategy(draw):
        obj = copy.deepcopy(base)
        for _ in range(draw(st.integers(1, max_ops))):
            paths = list(all_paths(obj))
            op = draw(st.sampled_from(["replace", "remove", "wrap", "deep", "swap", "add",
                                       "duplicate", "nudge", "replace"]))  # fmt: skip
            if not paths:
                op = "add"
            if op == "add":
                tables = [p for p in [(), *paths] if isinstance(get_at(obj, p), dict)]
                where = get_at(obj, draw(st.sampled_from(tables))) if tables else obj
                if isinstance(where, dict):
                    names = sorted({str(p[-1]) for p in paths if isinstance(p[-1], str)})
                    key = draw(st.sampled_from(names) | st.text(max_size=5)) if names else "k"
                    where[key] = draw(values(none))
                continue
            path = draw(st.sampled_from(paths))
            old = get_at(obj, path)
            parent = get_at(obj, path[:-1])
            if op == "replace":
                new = draw(values(none))
            elif op == "remove":
                del parent[path[-1]]
                continue
            elif op == "wrap":
                new = draw(st.sampled_from([[old], {"x": old}, [old, old]]))
            elif op == "deep":
                # (tomli_w cannot write arrays 400 deep: TOML documents go to 100)
                depth = draw(st.sampled_from([2, 20, 100, 400] if none else [2, 20, 100]))
                new = functools.reduce(lambda v, _: [v], range(depth), old)
            elif op == "swap":
                new = copy.deepcopy(get_at(obj, draw(st.sampled_from(paths))))
            elif op == "duplicate":
                if isinstance(old, list) and old:
                    i = draw(st.integers(0, len(old) - 1))
                    new = old[:i] + [copy.deepcopy(old[i])] + old[i:]
                elif isinstance(old, list):
                    new = [draw(values(none))]
                else:
                    new = [old, old]
            else:  # nudge a number
                if isinstance(old, bool) or not isinstance(old, (int, float)):
                    new = draw(values(none))
                elif isinstance(old, int):
                    new = old + draw(st.sampled_from([-1, 1, -(old or 1) * 2, 10**6])) if draw(
                        st.booleans()) else draw(special_ints)  # fmt: skip
                else:
                    new = draw(special_floats) if draw(st.booleans()) else old * draw(
                        st.sampled_from([-1.0, 1e3, 1e-3, 1e300]))  # fmt: skip
            parent[path[-1]] = new
        return obj

    return strategy()


_DTYPES = ["f8", "f4", "f2", "i8", "i1", "u8", "?", "c16", "M8[s]", "m8[s]", "U3", "S3", "O"]
_SPECIAL = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -1.0, 1e-300, 2.0**62]


def _reshaped(draw, st, a: np.ndarray) -> np.ndarray:
    """`a` with its shape changed (a draw of `mutated_arrays`)."""
    shape = draw(st.sampled_from(["scalar", "empty", "more", "less", "extra", "flat"]))
    if shape == "scalar":
        return np.array(a.reshape(-1)[0] if a.size else 1.0)
    if shape == "empty":
        return a[:0] if a.ndim else np.zeros(0)
    if shape == "more":
        return np.concatenate([a, a[-1:]]) if a.ndim and a.size else a
    if shape == "less":
        return a[:-1] if a.ndim else a
    if shape == "extra":
        return a[..., None]
    return a.reshape(-1)


def _damaged_bytes(draw, st, a: np.ndarray) -> bytes:
    """The .npy bytes of `a` damaged: bytes after its data, cut short, or bytes flipped."""
    data = npy_bytes(a)
    how = draw(st.sampled_from(["trailing", "cut", "flip"]))
    if how == "trailing":
        return data + b"\0" * draw(st.integers(1, 64))
    if how == "cut":
        return data[: draw(st.integers(0, len(data) - 1))]
    data = bytearray(data)
    for _ in range(draw(st.integers(1, 8))):
        data[draw(st.integers(0, len(data) - 1))] ^= 0xFF
    return bytes(data)


def mutated_arrays(bases: dict[str, dict[str, np.ndarray]], max_ops: int = 3):
    """A strategy: (arrays, raw) of an `.npz` from one of the valid `bases` with 1..max_ops
    mutations: a variable's dtype changed (complex, datetime, boolean, strings, bytes, objects,
    small floats and ints), its shape changed (scalar, empty, a row more or less, an extra or a
    missing dimension), special values put in (NaN, inf, huge, tiny), the variable removed,
    reversed or swapped for another, an unknown variable added; JSON strings (the vehicle)
    mutated as trees; and raw damage to a member (bytes after its data, cut short, bytes
    flipped). raw: {name: member bytes} for the damaged members."""
    st, _values, _sf, _si = _strategies()

    @st.composite
    def strategy(draw):
        arrays = dict(bases[draw(st.sampled_from(sorted(bases)))])
        raw: dict[str, bytes] = {}
        for _ in range(draw(st.integers(1, max_ops))):
            names = sorted(arrays)
            op = draw(st.sampled_from(["dtype", "shape", "values", "values", "remove", "add",
                                       "swap", "reverse", "raw", "json"]))  # fmt: skip
            if op == "add" or not names:
                arrays[draw(st.sampled_from(["extra", "scan_t2", "meta"]))] = np.zeros(3)
                continue
            k = draw(st.sampled_from(names))
            a = np.asarray(arrays[k])
            if op == "remove":
                del arrays[k]
                raw.pop(k, None)
            elif op == "swap":
                arrays[k] = arrays[draw(st.sampled_from(names))]
            elif op == "reverse":
                arrays[k] = a[::-1] if a.ndim else a
            elif op == "dtype":
                dt = draw(st.sampled_from(_DTYPES))
                try:
                    with np.errstate(all="ignore"), warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        arrays[k] = a.astype(dt) if dt != "O" else np.array([None, 1.0], object)
                except (TypeError, ValueError, OverflowError):
                    arrays[k] = np.zeros(a.shape, dt)
            elif op == "shape":
                arrays[k] = _reshaped(draw, st, a)
            elif op == "values":
                if a.dtype.kind in "fiu" and a.size:
                    b = a.astype(np.float64 if a.dtype.kind == "f" else np.int64)
                    flat = b.reshape(-1)
                    for _ in range(draw(st.integers(1, 3))):
                        i = draw(st.integers(0, flat.size - 1))
                        v = draw(st.sampled_from(_SPECIAL))
                        if b.dtype.kind in "iu":
                            v = draw(st.sampled_from([-1, 2**62, -(2**62), 10**6]))
                        flat[i] = v
                    arrays[k] = b
            elif op == "raw":
                raw[k] = _damaged_bytes(draw, st, a)
            elif op == "json" and a.dtype.kind == "U" and a.ndim == 0:
                try:
                    doc = json.loads(str(a))
                except ValueError:
                    continue
                new = draw(mutated_tree(doc, max_ops=2))
                arrays[k] = np.array(json.dumps(new))
        return arrays, raw

    return strategy()

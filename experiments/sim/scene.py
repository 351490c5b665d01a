"""The simulated 2D world: objects, their truth labels, and the JSON scene files.

World frame: x and y in metres (x east, y north in our scene files), headings theta in radians,
counter-clockwise from +x. Everything in this module is in the world frame.

Objects
  circles  pillars, tree trunks, posts and legs: centre (2,) m, radius m.
           kind "pillar" | "trunk" | "post" (lamp posts, sign poles) | "leg" (a person's leg)
  walls    building walls, low balusters, car bodies: open or closed polylines.
           kind "wall" | "baluster" | "car"
  bushes   shrubs: irregular closed polygons (clutter for the extractor).  kind "bush"
"post", "leg" and "car" are the clutter that fools a trunk extractor on real data
(`experiments.sim.clutter`); a scene's `truth_trunks` are its circles of kind "trunk" or
"pillar" only, while `truth_landmarks` keeps every circle (the label convention below).
Every object has a unique `name` and a `height_m` above flat ground (inf = taller than any laser);
an object no taller than the laser's scan plane is invisible to it (the paper's low balusters,
over which its laser at ~1.2 m "can see the object outside the balusters").

Truth labels (the per-beam `scan_labels` of a sequence file, datasets/FORMAT.md)
  0 .. L-1          scene.circles, in order (== rows of `scene.truth_landmarks`, (L, 3) [x, y, r])
  L .. L+W-1        scene.walls, in order (all segments of one polyline share its label)
  L+W .. L+W+K-1    scene.bushes, in order
  NO_RETURN_LABEL   -1: no return (nothing hit, or beyond the sensor's maximum range)
  MIXED_LABEL       -2: a mixed return at a depth jump (see `experiments.sim.simulate`)

Scene files: the bundled ones are `experiments/scenes/<name>.json`, package data
(`experiments.bundled`), so an installed wheel has them; any other file by its path. Schema in
`datasets/scenes/README.md`; `load_scene`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import numpy as np

from experiments.bundled import SCENE_SUFFIX, scene_names, scenes_dir
from experiments.errors import ConfigError, DataError
from experiments.sim.shapes import TrunkShape, trunk_outline
from slam.sequence import MIXED_LABEL, NO_RETURN_LABEL  # datasets/FORMAT.md's values

__all__ = [
    "CircleObject",
    "WallObject",
    "BushObject",
    "Scene",
    "load_scene",
    "scene_from_dict",
    "list_scenes",
    "make_bush",
    "scenes_dir",
    "shape_trunks",
    "NO_RETURN_LABEL",
    "MIXED_LABEL",
    "CIRCLE_KINDS",
    "WALL_KINDS",
    "LANDMARK_KINDS",
]

CIRCLE_KINDS = ("pillar", "trunk", "post", "leg")
WALL_KINDS = ("wall", "baluster", "car")
LANDMARK_KINDS = ("pillar", "trunk")  # the circles a trunk map should hold


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _check_name(owner: str, name: Any) -> str:
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{owner}.name: must be a non-empty string, got {name!r}")
    return name


def _check_height(owner: str, h: Any) -> float:
    if not _is_number(h) or not h > 0:  # inf allowed, NaN rejected by `not h > 0`
        raise ConfigError(f"{owner}.height_m: must be a positive number or inf, got {h!r}")
    return float(h)


def _points_array(owner: str, pts: Any, min_points: int) -> np.ndarray:
    try:
        a = np.array(pts, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{owner}.points_xy: cannot be read as an (P, 2) array ({exc})") from None
    if a.ndim != 2 or a.shape[1] != 2:
        raise ConfigError(f"{owner}.points_xy: expected shape (P, 2), got {a.shape}")
    if a.shape[0] < min_points:
        raise ConfigError(
            f"{owner}.points_xy: needs at least {min_points} points, got {a.shape[0]}"
        )
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{owner}.points_xy: all coordinates must be finite")
    return _readonly(a)


@dataclass(frozen=True, eq=False)
class CircleObject:
    """A pillar or tree trunk: a vertical cylinder, a circle in the scan plane.

    center_xy: (2,) m, world frame. radius_m: > 0. kind: "pillar" or "trunk".
    height_m: above the ground (inf = always in the scan plane).
    outline_xy: None (a circle), or (P, 2) m, world frame: the vertices of a cross-section
        that is not a circle (`experiments.sim.shapes`), ray-cast as a polygon with this
        object's label; then center_xy is its centroid and radius_m its equal-area radius.
    """

    name: str
    center_xy: np.ndarray
    radius_m: float
    kind: str = "trunk"
    height_m: float = math.inf
    outline_xy: np.ndarray | None = None

    def __post_init__(self) -> None:
        owner = f"CircleObject({self.name!r})"
        _check_name("CircleObject", self.name)
        c = np.array(self.center_xy, dtype=np.float64)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ConfigError(
                f"{owner}.center_xy: expected 2 finite numbers, got {self.center_xy!r}"
            )
        object.__setattr__(self, "center_xy", _readonly(c))
        r = self.radius_m
        if not _is_number(r) or not math.isfinite(r) or r <= 0:
            raise ConfigError(f"{owner}.radius_m: must be a finite number > 0, got {r!r}")
        object.__setattr__(self, "radius_m", float(r))
        if self.kind not in CIRCLE_KINDS:
            raise ConfigError(f"{owner}.kind: must be one of {CIRCLE_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "height_m", _check_height(owner, self.height_m))
        if self.outline_xy is not None:
            object.__setattr__(self, "outline_xy", _points_array(owner, self.outline_xy, 3))

    @property
    def segments_xy(self) -> np.ndarray:
        """(P, 2, 2) the outline's edges, m (only when `outline_xy` is given)."""
        p = self.outline_xy
        return np.stack([p, np.roll(p, -1, axis=0)], axis=1)


@dataclass(frozen=True, eq=False)
class WallObject:
    """A wall or low baluster: a polyline of straight segments.

    points_xy: (P, 2) m, P >= 2, world frame; consecutive points distinct.
    closed: if True, the last point joins the first (a building outline).
    kind: "wall", "baluster" or "car". height_m: above the ground (inf = always in the scan plane).
    """

    name: str
    points_xy: np.ndarray
    kind: str = "wall"
    closed: bool = False
    height_m: float = math.inf

    def __post_init__(self) -> None:
        owner = f"WallObject({self.name!r})"
        _check_name("WallObject", self.name)
        p = _points_array(owner, self.points_xy, 2)
        object.__setattr__(self, "points_xy", p)
        if self.kind not in WALL_KINDS:
            raise ConfigError(f"{owner}.kind: must be one of {WALL_KINDS}, got {self.kind!r}")
        if not isinstance(self.closed, (bool, np.bool_)):
            raise ConfigError(f"{owner}.closed: must be true or false, got {self.closed!r}")
        object.__setattr__(self, "closed", bool(self.closed))
        seg = self.segments_xy
        if np.any(np.hypot(*(seg[:, 1] - seg[:, 0]).T) == 0.0):
            raise ConfigError(
                f"{owner}.points_xy: two consecutive points coincide (zero-length segment)"
            )
        object.__setattr__(self, "height_m", _check_height(owner, self.height_m))

    @property
    def segments_xy(self) -> np.ndarray:
        """(S, 2, 2) the polyline's segments [[x0, y0], [x1, y1]], m."""
        p = self.points_xy
        q = np.vstack([p, p[:1]]) if self.closed else p
        return np.stack([q[:-1], q[1:]], axis=1)


@dataclass(frozen=True, eq=False)
class BushObject:
    """A shrub: an irregular closed polygon (the extractor should call it clutter).

    points_xy: (P, 2) m, P >= 3 vertices, world frame; the last joins the first.
    height_m: above the ground (inf = always in the scan plane).
    """

    name: str
    points_xy: np.ndarray
    height_m: float = math.inf
    kind: str = field(default="bush", init=False)

    def __post_init__(self) -> None:
        owner = f"BushObject({self.name!r})"
        _check_name("BushObject", self.name)
        p = _points_array(owner, self.points_xy, 3)
        object.__setattr__(self, "points_xy", p)
        x, y = p[:, 0], p[:, 1]
        area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        if not area > 0:
            raise ConfigError(f"{owner}.points_xy: polygon has zero area")
        q = np.vstack([p, p[:1]])
        if np.any(np.hypot(*(q[1:] - q[:-1]).T) == 0.0):
            raise ConfigError(f"{owner}.points_xy: two consecutive vertices coincide")
        object.__setattr__(self, "height_m", _check_height(owner, self.height_m))

    @property
    def segments_xy(self) -> np.ndarray:
        """(P, 2, 2) the polygon's edges, m."""
        p = self.points_xy
        return np.stack([p, np.roll(p, -1, axis=0)], axis=1)

    @property
    def bounding_circle(self) -> tuple[np.ndarray, float]:
        """A circle containing the polygon: (centre (2,), radius m), about the vertex centroid."""
        c = self.points_xy.mean(axis=0)
        return c, float(np.max(np.hypot(*(self.points_xy - c).T)))


@dataclass(frozen=True, eq=False)
class Scene:
    """A 2D world for the laser simulator, with named objects and scan positions.

    circles, walls, bushes: the objects (see the module docstring for the label order).
    scan_positions: (S, 3) [x, y, theta] m, m, rad: named places to scan from (may be empty).
    scan_position_names: (S,) their names ("1".."S" when not given).
    name, description: free text.
    """

    circles: tuple[CircleObject, ...] = ()
    walls: tuple[WallObject, ...] = ()
    bushes: tuple[BushObject, ...] = ()
    scan_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    scan_position_names: tuple[str, ...] = ()
    name: str = ""
    description: str = ""

    def __post_init__(self) -> None:
        for fname, typ in (
            ("circles", CircleObject),
            ("walls", WallObject),
            ("bushes", BushObject),
        ):
            objs = tuple(getattr(self, fname))
            for i, o in enumerate(objs):
                if not isinstance(o, typ):
                    raise ConfigError(
                        f"Scene.{fname}[{i}]: expected {typ.__name__}, got {type(o).__name__}"
                    )
            object.__setattr__(self, fname, objs)
        names = [o.name for o in self.objects]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(f"Scene: object names must be unique, repeated: {dup}")
        sp = np.array(self.scan_positions, dtype=np.float64)
        if sp.size == 0:
            sp = np.zeros((0, 3))
        if sp.ndim != 2 or sp.shape[1] != 3 or not np.all(np.isfinite(sp)):
            raise ConfigError(
                f"Scene.scan_positions: expected finite (S, 3) [x, y, theta], got shape {sp.shape}"
            )
        object.__setattr__(self, "scan_positions", _readonly(sp))
        spn = tuple(self.scan_position_names) or tuple(str(i + 1) for i in range(sp.shape[0]))
        if len(spn) != sp.shape[0] or not all(isinstance(s, str) for s in spn):
            raise ConfigError(
                f"Scene.scan_position_names: expected {sp.shape[0]} strings, "
                f"got {self.scan_position_names!r}"
            )
        object.__setattr__(self, "scan_position_names", spn)
        kinds = [o.kind for o in self.objects]
        # Lookup tables indexed by label + 2 (so MIXED_LABEL -> 0, NO_RETURN_LABEL -> 1).
        object.__setattr__(self, "_kind_lut", np.array(["mixed", "none", *kinds]))
        groups = (
            ["circle"] * len(self.circles)
            + ["wall"] * len(self.walls)
            + ["bush"] * len(self.bushes)
        )
        object.__setattr__(self, "_group_lut", np.array(["mixed", "none", *groups]))
        object.__setattr__(self, "_name_lut", np.array(["<mixed>", "<none>", *names]))
        object.__setattr__(self, "_label_of", {n: i for i, n in enumerate(names)})
        object.__setattr__(self, "_geometry_cache", {})

    # ---- objects and labels ------------------------------------------------------------------

    @property
    def objects(self) -> tuple[CircleObject | WallObject | BushObject, ...]:
        """All objects in label order: circles, walls, bushes."""
        return (*self.circles, *self.walls, *self.bushes)

    @property
    def n_objects(self) -> int:
        return len(self.circles) + len(self.walls) + len(self.bushes)

    @property
    def truth_landmarks(self) -> np.ndarray:
        """(L, 3) [x, y, r] of scene.circles, m; row i has label i."""
        if not self.circles:
            return np.zeros((0, 3))
        return np.array([[*c.center_xy, c.radius_m] for c in self.circles])

    @property
    def truth_trunks(self) -> np.ndarray:
        """(T,) labels of the circles a trunk map should hold (kind in `LANDMARK_KINDS`); every
        circle of a scene without posts or legs."""
        return np.array(
            [i for i, c in enumerate(self.circles) if c.kind in LANDMARK_KINDS], dtype=np.int64
        )

    def label_of(self, name: str) -> int:
        """The label of the object called `name`."""
        try:
            return self._label_of[name]
        except KeyError:
            raise ConfigError(f"Scene {self.name!r}: no object named {name!r}") from None

    def _lut(self, lut: np.ndarray, labels: Any) -> np.ndarray:
        lab = np.asarray(labels)
        if lab.dtype.kind not in "iu":
            raise ConfigError(f"labels: expected integers, got dtype {lab.dtype}")
        if lab.size and (lab.min() < MIXED_LABEL or lab.max() >= self.n_objects):
            raise ConfigError(
                f"labels: must lie in [{MIXED_LABEL}, {self.n_objects - 1}] for scene "
                f"{self.name!r}, got [{lab.min()}, {lab.max()}]"
            )
        return lut[lab + 2]

    def label_kind(self, labels: Any) -> np.ndarray:
        """Kind of the object behind each label: "pillar", "trunk", "wall", "baluster", "bush",
        "none" (-1) or "mixed" (-2). Same shape as `labels`, numpy str array."""
        return self._lut(self._kind_lut, labels)

    def label_group(self, labels: Any) -> np.ndarray:
        """Coarse class of each label: "circle", "wall" (walls and balusters), "bush", "none",
        "mixed"."""
        return self._lut(self._group_lut, labels)

    def label_name(self, labels: Any) -> np.ndarray:
        """Object name of each label ("<none>", "<mixed>" for -1, -2)."""
        return self._lut(self._name_lut, labels)

    # ---- flat geometry for the ray caster ----------------------------------------------------

    def geometry(self, plane_height_m: float = 0.0) -> dict[str, np.ndarray]:
        """Flat arrays of the objects that reach above `plane_height_m`, cached per height.

        circ_xyr (Lc, 3) [x, y, r] m, circ_label (Lc,); seg_p (S, 2) segment starts, seg_e (S, 2)
        end - start, m, seg_label (S,): every wall segment and every bush edge, then the edges
        of the circles given an `outline_xy` (with the circle's label). Also column
        forms for `raycast`: pts_x, pts_y (Lc + 2S,) circle centres, segment starts, segment
        ends; circ_r2; seg_ex, seg_ey; seg_tol (collinearity tolerance); obj_label (Lc + S,).
        """
        key = float(plane_height_m)
        cache = self._geometry_cache
        if key in cache:
            return cache[key]
        L, W = len(self.circles), len(self.walls)
        circ = [
            (i, c) for i, c in enumerate(self.circles) if c.height_m > key and c.outline_xy is None
        ]
        circ_xyr = np.array([[*c.center_xy, c.radius_m] for _, c in circ]).reshape(-1, 3)
        circ_label = np.array([i for i, _ in circ], dtype=np.int64)
        segs, seg_label = [np.zeros((0, 2, 2))], [np.zeros(0, dtype=np.int64)]
        polys = [(L + j, w) for j, w in enumerate(self.walls)]
        polys += [(L + W + k, b) for k, b in enumerate(self.bushes)]
        polys += [(i, c) for i, c in enumerate(self.circles) if c.outline_xy is not None]
        for lab, o in polys:
            if o.height_m > key:
                sg = o.segments_xy
                segs.append(sg)
                seg_label.append(np.full(sg.shape[0], lab, dtype=np.int64))
        seg = np.concatenate(segs)
        e = seg[:, 1] - seg[:, 0]
        seg_label = np.concatenate(seg_label)
        # Column forms for the ray caster: one array each, circles then segments.
        pts = np.concatenate([circ_xyr[:, :2], seg[:, 0], seg[:, 1]])  # centres, starts, ends
        geo = {
            "circ_xyr": circ_xyr,
            "circ_label": circ_label,
            "seg_p": np.ascontiguousarray(seg[:, 0]),
            "seg_e": e,
            "seg_label": seg_label,
            "pts_x": pts[:, 0].copy(),
            "pts_y": pts[:, 1].copy(),
            "circ_r2": circ_xyr[:, 2] ** 2,
            "seg_ex": e[:, 0].copy(),
            "seg_ey": e[:, 1].copy(),
            "seg_tol": 1e-12 * np.maximum(1.0, np.sum(e * e, axis=1)),
            "obj_label": np.concatenate([circ_label, seg_label]),
        }
        for v in geo.values():
            _readonly(v)
        cache[key] = geo
        return geo

    def bounds_xy(self) -> np.ndarray:
        """(2, 2) [[xmin, ymin], [xmax, ymax]] of all objects and scan positions, m."""
        pts = [c.center_xy + s * c.radius_m for c in self.circles for s in (-1, 1)]
        pts += [p for c in self.circles if c.outline_xy is not None for p in c.outline_xy]
        pts += [p for o in (*self.walls, *self.bushes) for p in o.points_xy]
        pts += list(self.scan_positions[:, :2])
        if not pts:
            return np.zeros((2, 2))
        a = np.array(pts)
        return np.array([a.min(axis=0), a.max(axis=0)])


# ---- scene files ---------------------------------------------------------------------------

_TOP_KEYS = {
    "description",
    "schema",
    "name",
    "frame",
    "notes",
    "circles",
    "walls",
    "bushes",
    "scan_positions",
    "scan_position_names",
    "trunk_shape",
}
_SHAPE_KEYS = {"aspect", "lobes", "lobe_amplitude", "seed", "n_vertices", "note"}
_CIRCLE_KEYS = {"name", "kind", "center_xy", "radius_m", "height_m", "note"}
_WALL_KEYS = {"name", "kind", "points_xy", "closed", "height_m", "note"}
_BUSH_KEYS = {"name", "points_xy", "height_m", "note"}
SCHEMA = "trunkslam-scene/1"


def list_scenes() -> list[str]:
    """Names of the bundled scenes (file stems in `experiments/scenes/`)."""
    return scene_names()


def _resolve(name_or_path: str | Path) -> Path | Traversable:
    s = str(name_or_path)
    is_path = isinstance(name_or_path, Path) or s.endswith(".json") or "/" in s or "\\" in s
    if is_path:
        p = Path(name_or_path)
        if not p.is_file() and p.parent == Path(".") and (scenes_dir() / p.name).is_file():
            return scenes_dir() / p.name  # "pillar_court.json": a bundled scene by file name
        if not p.is_file():
            raise DataError(f"scene file not found: {p}")
        return p
    p = scenes_dir() / f"{s}{SCENE_SUFFIX}"
    if not p.is_file():
        raise DataError(
            f"scene {s!r} not found: no file {p}; "
            f"bundled scenes: {', '.join(list_scenes()) or 'none'}"
        )
    return p


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a scene by name (a bundled one, `experiments/scenes/NAME.json`) or by path to a
    `.json` file.

    Raises `DataError` (a `ValueError`) naming the file and the offending key.
    """
    path = _resolve(name_or_path)
    try:
        # an integer too long for a float becomes inf (refused as not finite), not a huge int
        data = json.loads(
            path.read_text(encoding="utf-8"),
            parse_int=lambda t: int(t) if len(t) < 300 else float(t),
        )
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise DataError(f"{path}: JSON nested too deeply to be a scene") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot read ({exc})") from None
    return scene_from_dict(data, source=str(path), default_name=Path(path.name).stem)


def _where(source: str, key: str) -> str:
    return f"{source}: {key}"


def _get(
    obj: Mapping, key: str, where: str, source: str, required: bool = True, default: Any = None
) -> Any:
    if key in obj:
        return obj[key]
    if required:
        raise DataError(_where(source, f"{where}: missing required key {key!r}"))
    return default


def _number(v: Any, where: str, source: str, positive: bool = False) -> float:
    if not _is_number(v) or not math.isfinite(v) or (positive and v <= 0):
        need = "a finite number > 0" if positive else "a finite number"
        raise DataError(_where(source, f"{where}: must be {need}, got {v!r}"))
    return float(v)


def _height(obj: Mapping, where: str, source: str) -> float:
    h = obj.get("height_m")
    return math.inf if h is None else _number(h, f"{where}.height_m", source, positive=True)


def _xy_list(v: Any, where: str, source: str, min_points: int) -> np.ndarray:
    if not isinstance(v, list) or len(v) < min_points:
        raise DataError(
            _where(source, f"{where}: must be a list of at least {min_points} [x, y] pairs")
        )
    out = np.empty((len(v), 2))
    for i, p in enumerate(v):
        if not isinstance(p, list) or len(p) != 2:
            raise DataError(_where(source, f"{where}[{i}]: must be an [x, y] pair, got {p!r}"))
        out[i] = [
            _number(p[0], f"{where}[{i}][0]", source),
            _number(p[1], f"{where}[{i}][1]", source),
        ]
    return out


def _text(obj: Mapping, key: str, where: str, source: str, lines: bool = False) -> str | None:
    """A free-text key (a string; with `lines`, or a list of strings, one per line); None when
    absent."""
    if key not in obj:
        return None
    v = obj[key]
    if lines and isinstance(v, list) and all(isinstance(s, str) for s in v):
        return "\n".join(v)
    if not isinstance(v, str):
        need = "a string or a list of strings" if lines else "a string"
        shown = type(v).__name__ if isinstance(v, (list, dict)) else repr(v)[:40]
        raise DataError(_where(source, f"{where}{key}: must be {need}, got {shown}"))
    return v


def _check_keys(obj: Any, allowed: set[str], where: str, source: str) -> None:
    if not isinstance(obj, dict):
        raise DataError(_where(source, f"{where}: must be a JSON object, got {type(obj).__name__}"))
    extra = sorted(set(obj) - allowed)
    if extra:
        raise DataError(
            _where(source, f"{where}: unknown key(s) {extra}; allowed: {sorted(allowed)}")
        )


def _list(data: Mapping, key: str, source: str) -> list:
    v = data.get(key, [])
    if not isinstance(v, list):
        raise DataError(_where(source, f"{key}: must be a list, got {type(v).__name__}"))
    return v


def _circle(c: Any, w: str, source: str) -> CircleObject:
    """One entry of "circles" (`w`: where it is, for errors)."""
    _check_keys(c, _CIRCLE_KEYS, w, source)
    _text(c, "note", f"{w}.", source)
    name = _get(c, "name", w, source)
    center = _xy_list([_get(c, "center_xy", w, source)], f"{w}.center_xy", source, 1)[0]
    r = _number(_get(c, "radius_m", w, source), f"{w}.radius_m", source, positive=True)
    kind = _kind(c, CIRCLE_KINDS, "trunk", w, source)
    return CircleObject(name, center, r, kind, _height(c, w, source))


def _kind(o: Mapping, kinds: tuple[str, ...], default: str, w: str, source: str) -> str:
    """The entry's "kind", one of `kinds` (absent: `default`)."""
    kind = o.get("kind", default)
    if kind not in kinds:
        raise DataError(_where(source, f"{w}.kind: must be one of {kinds}, got {kind!r}"))
    return kind


def _wall(o: Any, w: str, source: str) -> WallObject:
    """One entry of "walls"."""
    _check_keys(o, _WALL_KEYS, w, source)
    _text(o, "note", f"{w}.", source)
    name = _get(o, "name", w, source)
    pts = _xy_list(_get(o, "points_xy", w, source), f"{w}.points_xy", source, 2)
    kind = _kind(o, WALL_KINDS, "wall", w, source)
    closed = o.get("closed", False)
    if not isinstance(closed, bool):
        raise DataError(_where(source, f"{w}.closed: must be true or false, got {closed!r}"))
    return WallObject(name, pts, kind, closed, _height(o, w, source))


def _bush(o: Any, w: str, source: str) -> BushObject:
    """One entry of "bushes"."""
    _check_keys(o, _BUSH_KEYS, w, source)
    _text(o, "note", f"{w}.", source)
    name = _get(o, "name", w, source)
    pts = _xy_list(_get(o, "points_xy", w, source), f"{w}.points_xy", source, 3)
    return BushObject(name, pts, _height(o, w, source))


def _scan_positions(data: Mapping, source: str) -> tuple[np.ndarray, tuple]:
    """(scan_positions (P, 3) [x, y, theta], their names (P,) or ())."""
    sp_raw = _list(data, "scan_positions", source)
    sp = np.zeros((len(sp_raw), 3))
    for i, p in enumerate(sp_raw):
        if not isinstance(p, list) or len(p) != 3:
            raise DataError(
                _where(source, f"scan_positions[{i}]: must be [x, y, theta], got {p!r}")
            )
        sp[i] = [_number(v, f"scan_positions[{i}][{j}]", source) for j, v in enumerate(p)]
    spn = data.get("scan_position_names", [])
    if not isinstance(spn, list) or (spn and len(spn) != len(sp_raw)):
        raise DataError(
            _where(source, f"scan_position_names: must be a list of {len(sp_raw)} strings")
        )
    return sp, tuple(spn)


def scene_from_dict(data: Mapping, source: str = "<dict>", default_name: str = "") -> Scene:
    """Build a `Scene` from the parsed JSON schema of `datasets/scenes/README.md`.

    `source` prefixes error messages (the file path for `load_scene`).
    """
    _check_keys(data, _TOP_KEYS, "top level", source)
    schema = data.get("schema", SCHEMA)
    if schema != SCHEMA:
        raise DataError(_where(source, f"schema: expected {SCHEMA!r}, got {schema!r}"))
    if not any(k in data for k in ("circles", "walls", "bushes")):
        raise DataError(
            _where(source, "top level: needs at least one of 'circles', 'walls', 'bushes'")
        )
    try:
        circles = [
            _circle(c, f"circles[{i}]", source)
            for i, c in enumerate(_list(data, "circles", source))
        ]
        walls = [
            _wall(o, f"walls[{i}]", source) for i, o in enumerate(_list(data, "walls", source))
        ]
        bushes = [
            _bush(o, f"bushes[{i}]", source) for i, o in enumerate(_list(data, "bushes", source))
        ]
        sp, spn = _scan_positions(data, source)
        name = _text(data, "name", "", source) or default_name
        # long descriptions and notes may be a list of lines
        description = _text(data, "description", "", source, lines=True) or ""
        _text(data, "notes", "", source, lines=True)
        _text(data, "frame", "", source)
        scene = Scene(
            circles=tuple(circles),
            walls=tuple(walls),
            bushes=tuple(bushes),
            scan_positions=sp,
            scan_position_names=spn,
            name=str(name),
            description=str(description),
        )
        return shape_trunks(scene, _trunk_shape(data, source))
    except DataError:
        raise
    except ValueError as exc:  # an object's own validation (names, zero-length segments, ...)
        raise DataError(_where(source, str(exc))) from None


def _trunk_shape(data: Mapping, source: str) -> TrunkShape:
    """The file's "trunk_shape" (absent: circles)."""
    v = data.get("trunk_shape", {})
    _check_keys(v, _SHAPE_KEYS, "trunk_shape", source)
    _text(v, "note", "trunk_shape.", source)
    try:
        return TrunkShape(**{k: x for k, x in v.items() if k != "note"})
    except ConfigError as exc:
        raise DataError(_where(source, f"trunk_shape: {exc}")) from None


def shape_trunks(scene: Scene, shape: TrunkShape) -> Scene:
    """`scene` with every circle of kind "trunk" given `shape`'s outline
    (`experiments.sim.shapes`; centre and equal-area radius kept, so the truth tables are
    unchanged); the scene itself when the shape is a circle. Labels and order are kept."""
    if not isinstance(shape, TrunkShape):
        raise ConfigError(f"shape_trunks.shape: expected a TrunkShape, got {type(shape).__name__}")
    if shape.is_circle:
        return scene
    trunks = [i for i, c in enumerate(scene.circles) if c.kind == "trunk"]
    draws = shape.draws(len(trunks))
    circles = list(scene.circles)
    for i, (orientation, phase) in zip(trunks, draws):
        c = circles[i]
        outline = trunk_outline(c.center_xy, c.radius_m, shape, orientation, phase)
        circles[i] = replace(c, outline_xy=outline)
    return Scene(
        circles=tuple(circles),
        walls=scene.walls,
        bushes=scene.bushes,
        scan_positions=scene.scan_positions,
        scan_position_names=scene.scan_position_names,
        name=scene.name,
        description=scene.description,
    )


def make_bush(
    center_xy: Iterable[float],
    mean_radius_m: float,
    rng: np.random.Generator,
    n_vertices: int = 12,
    irregularity: float = 0.35,
) -> np.ndarray:
    """An irregular, star-shaped (hence simple) polygon: (n_vertices, 2) vertices, m, CCW.

    Vertex k sits at angle 2 pi (k + u_k) / n (u_k ~ U(-0.3, 0.3)) and radius
    mean_radius_m * (1 + irregularity * z_k), z_k ~ U(-1, 1), so the outline is bumpy, not an arc.
    Used to write the bush outlines of the bundled scene files.
    """
    if not mean_radius_m > 0:
        raise ConfigError(f"make_bush.mean_radius_m: must be > 0, got {mean_radius_m!r}")
    if n_vertices < 3:
        raise ConfigError(f"make_bush.n_vertices: must be >= 3, got {n_vertices!r}")
    if not 0 <= irregularity < 1:
        raise ConfigError(f"make_bush.irregularity: must be in [0, 1), got {irregularity!r}")
    c = np.asarray(tuple(center_xy), dtype=np.float64)
    k = np.arange(n_vertices)
    ang = 2 * np.pi * (k + rng.uniform(-0.3, 0.3, n_vertices)) / n_vertices
    rad = mean_radius_m * (1 + irregularity * rng.uniform(-1, 1, n_vertices))
    return c + np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)

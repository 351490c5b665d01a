"""2D pose-landmark graph files in the g2o/TORO text conventions GTSAM's `readG2o` reads
(`gtsam/slam/dataset.cpp`, `load2D` with the g2o noise format), as a `slam.graph.PoseGraph2D`.

One record per line, fields separated by blanks; angles in rad, lengths in m:

    VERTEX_SE2 id x y theta             a pose's starting value (also VERTEX2, VERTEX)
    VERTEX_XY id x y                    a landmark's starting value
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33
                                        odometry: pose j in the frame of pose i, with the upper
                                        triangle of its information matrix, row by row (also
                                        EDGE2, EDGE, ODOMETRY)
    BR i l bearing range sigma_bearing sigma_range
                                        landmark l seen from pose i, independent noise
    LANDMARK i l x y v1 v2 v3           landmark l at (x, y) in the frame of pose i, turned into
                                        a bearing-range measurement as GTSAM does: sigma_bearing
                                        = sqrt(v1 / 10), sigma_range = sqrt(v1) when |v1 - v3| <
                                        1e-4, else both 1
    FIX i                               g2o's gauge fix: the solver holds pose i in place
    # ...                               a comment

Poses and landmarks are separate id spaces (GTSAM keys them i and L(l)). A value missing from
the file is filled as readG2o fills it, factor by factor in file order: an odometry factor's
first pose at the origin, its second composed from the first; a landmark from its first
measurement. `edge_noise="covariance"` reads the six numbers of an odometry line as the upper
triangle of a covariance instead of an information matrix: GTSAM's own `victoria_park.txt`
holds covariances (its `load2D` guesses so from the zeros; `readG2o` takes them for
information, as g2o does). Any other tag is an error naming the line; `skip` names tags to
pass over instead (GTSAM passes over every tag it does not know, e.g. the LANDMARK2 lines of
its victoriaPark_reduced_1k.g2o and cityTrees_reduced_1k.g2o).

`g2o_text` writes a graph with VERTEX_SE2, VERTEX_XY, EDGE_SE2 and BR lines only (17
significant digits: the file reads back to the same doubles). No comment and no FIX: GTSAM
4.3's readG2o reads no factor after either (tests/experiments/test_graph_files.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from slam import se2
from slam.errors import SlamError
from slam.graph import PoseGraph2D

__all__ = ["EDGE_NOISE", "G2O_TAGS", "G2oFile", "g2o_text", "read_g2o"]

POSE_TAGS = ("VERTEX_SE2", "VERTEX2", "VERTEX")
EDGE_TAGS = ("EDGE_SE2", "EDGE2", "EDGE", "ODOMETRY")
# tag -> the number of fields after it
_FIELDS = {
    **dict.fromkeys(POSE_TAGS, 4),
    "VERTEX_XY": 3,
    **dict.fromkeys(EDGE_TAGS, 11),
    "BR": 6,
    "LANDMARK": 7,
    "FIX": 1,
}
G2O_TAGS = tuple(_FIELDS)


@dataclass(frozen=True)
class G2oFile:
    """A graph file read: the graph, the poses FIX lines name, and the lines skipped by tag."""

    graph: PoseGraph2D
    fixed: tuple[int, ...] = ()
    skipped: dict[str, int] = field(default_factory=dict)


class _Builder:
    """The file's records in order, and the starting values filled as readG2o fills them."""

    def __init__(self, covariance: bool = False) -> None:
        self.covariance = covariance
        self.pose: dict[int, np.ndarray] = {}
        self.landmark: dict[int, np.ndarray] = {}
        self.odo: list[tuple] = []
        self.br: list[tuple] = []
        self.fixed: list[int] = []

    def vertex(self, tag: str, v: list[float], where: str) -> None:
        i = _id(v[0], where)
        table = self.landmark if tag == "VERTEX_XY" else self.pose
        if i in table:
            raise DataError(f"{where}: {tag} {i} given twice")
        table[i] = np.array(v[1:], dtype=np.float64)

    def factor(self, tag: str, v: list[float], where: str) -> None:
        i, j = _id(v[0], where), _id(v[1], where)
        if tag in EDGE_TAGS:
            info = np.array([[v[5], v[6], v[7]], [v[6], v[8], v[9]], [v[7], v[9], v[10]]])
            if np.linalg.eigvalsh(info).min() <= 0:
                what = "covariance" if self.covariance else "information matrix"
                raise DataError(f"{where}: {tag}: not a positive definite {what}")
            if self.covariance:
                info = np.linalg.inv(info)
            self.odo.append((i, j, np.array(v[2:5]), info))
            self.pose.setdefault(i, np.zeros(3))
            if j not in self.pose:
                q = se2.compose(self.pose[i], np.array(v[2:5]))
                q[2] = float(se2.wrap_angle(q[2]))
                self.pose[j] = q
            return
        if tag == "BR":
            bearing, rng, sigma = v[2], v[3], (v[4], v[5])
        else:  # LANDMARK, as GTSAM's load2D converts it
            bearing, rng = math.atan2(v[3], v[2]), math.hypot(v[2], v[3])
            same = abs(v[4] - v[6]) < 1e-4
            sigma = (math.sqrt(v[4] / 10.0), math.sqrt(v[4])) if same else (1.0, 1.0)
        if not (rng > 0 and min(sigma) > 0):
            raise DataError(f"{where}: {tag}: the range and standard deviations must be > 0")
        self.br.append((i, j, bearing, rng, sigma))
        p = self.pose.setdefault(i, np.zeros(3))
        if j not in self.landmark:
            local = np.array([rng * math.cos(bearing), rng * math.sin(bearing)])
            self.landmark[j] = se2.transform_points(p, local)

    def graph(self) -> PoseGraph2D:
        pid = np.array(sorted(self.pose), np.int64)
        lid = np.array(sorted(self.landmark), np.int64)
        odo = list(zip(*self.odo)) if self.odo else [(), (), (), ()]
        br = list(zip(*self.br)) if self.br else [(), (), (), (), ()]
        return PoseGraph2D(
            pose_id=pid,
            pose=np.array([self.pose[i] for i in pid]).reshape(-1, 3),
            landmark_id=lid,
            landmark_xy=np.array([self.landmark[i] for i in lid]).reshape(-1, 2),
            odo_from=np.array(odo[0], np.int64),
            odo_to=np.array(odo[1], np.int64),
            odo_delta=np.array(odo[2]).reshape(-1, 3),
            odo_info=np.array(odo[3]).reshape(-1, 3, 3),
            br_pose=np.array(br[0], np.int64),
            br_landmark=np.array(br[1], np.int64),
            br_bearing=np.array(br[2], np.float64),
            br_range=np.array(br[3], np.float64),
            br_sigma=np.array(br[4], np.float64).reshape(-1, 2),
        )


def _id(x: float, where: str) -> int:
    if not (x == int(x) and 0 <= x < 2**53):
        raise DataError(f"{where}: id {x!r} is not an integer >= 0")
    return int(x)


def _fields(path: Path, n: int, parts: list[str]) -> list[float]:
    tag, want = parts[0], _FIELDS[parts[0]]
    where = f"{path} line {n}"
    if len(parts) - 1 != want:
        raise DataError(f"{where}: {tag} expects {want} numbers, got {len(parts) - 1}")
    try:
        v = [float(x) for x in parts[1:]]
    except ValueError as e:
        raise DataError(f"{where}: {tag}: {e}") from None
    if not all(math.isfinite(x) for x in v):
        raise DataError(f"{where}: {tag}: NaN or infinite value")
    return v


EDGE_NOISE = ("information", "covariance")


def read_g2o(
    path: Path | str, skip: tuple[str, ...] | list[str] = (), edge_noise: str = "information"
) -> G2oFile:
    """The graph of the file at `path` (module doc); `skip`: tags to pass over; edge_noise:
    "information" (g2o's) or "covariance", what an odometry line's six numbers are."""
    if edge_noise not in EDGE_NOISE:
        raise DataError(f"edge_noise: expected one of {list(EDGE_NOISE)}, got {edge_noise!r}")
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: no such graph file")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as e:
        raise DataError(f"{path}: not a text graph file") from e
    b = _Builder(covariance=edge_noise == "covariance")
    skipped: dict[str, int] = {}
    records = []
    for n, line in enumerate(lines, start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        tag = parts[0]
        if tag in skip:
            skipped[tag] = skipped.get(tag, 0) + 1
            continue
        if tag not in _FIELDS:
            raise DataError(
                f"{path} line {n}: unknown tag {tag!r} (read: {', '.join(G2O_TAGS)}; to pass "
                "over a tag, as GTSAM's readG2o does, skip it)"
            )
        records.append((n, tag, _fields(path, n, parts)))
    for n, tag, v in records:  # the vertices first, as readG2o reads them
        if tag in POSE_TAGS or tag == "VERTEX_XY":
            b.vertex(tag, v, f"{path} line {n}")
        elif tag == "FIX":
            b.fixed.append(_id(v[0], f"{path} line {n}"))
    for n, tag, v in records:
        if tag in EDGE_TAGS or tag in ("BR", "LANDMARK"):
            b.factor(tag, v, f"{path} line {n}")
    if not b.pose:
        raise DataError(f"{path}: no pose (not a 2D graph file?)")
    try:
        graph = b.graph()
    except SlamError as e:
        raise DataError(f"{path}: {e}") from e
    unknown = [i for i in b.fixed if i not in b.pose]
    if unknown:
        raise DataError(f"{path}: FIX {unknown[0]}: no such pose")
    return G2oFile(graph=graph, fixed=tuple(b.fixed), skipped=skipped)


def _g(x: float) -> str:
    return f"{float(x):.17g}"


def g2o_text(graph: PoseGraph2D) -> str:
    """The graph as g2o text: VERTEX_SE2, VERTEX_XY, EDGE_SE2 and BR lines, nothing else
    (GTSAM 4.3's readG2o stops reading factors at a comment or a FIX line)."""
    out = []
    for i, p in zip(graph.pose_id, graph.pose):
        out.append(f"VERTEX_SE2 {i} {_g(p[0])} {_g(p[1])} {_g(p[2])}")
    for i, p in zip(graph.landmark_id, graph.landmark_xy):
        out.append(f"VERTEX_XY {i} {_g(p[0])} {_g(p[1])}")
    upper = np.triu_indices(3)
    for i, j, d, info in zip(graph.odo_from, graph.odo_to, graph.odo_delta, graph.odo_info):
        nums = " ".join(_g(x) for x in (*d, *info[upper]))
        out.append(f"EDGE_SE2 {i} {j} {nums}")
    for i, j, b, r, s in zip(
        graph.br_pose, graph.br_landmark, graph.br_bearing, graph.br_range, graph.br_sigma
    ):
        out.append(f"BR {i} {j} {_g(b)} {_g(r)} {_g(s[0])} {_g(s[1])}")
    return "\n".join(out) + "\n"

"""Graph files: `trunkslam export-graph RUN --format g2o` writes a run's pose-landmark graph;
`trunkslam smooth GRAPH.g2o` solves one (`experiments.io.g2o`, `slam.smoother.solve_pose_graph`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.g2o import g2o_text, read_g2o
from experiments.io.outputs import check_outputs, check_run_export
from experiments.io.run_log import read_run_log
from experiments.io.writers import write_atomic
from slam.graph import PoseGraph2D, graph_of_problem

__all__ = ["GRAPH_FORMATS", "ExportedGraph", "export_graph", "smooth_graph_file"]

GRAPH_FORMATS = ("g2o",)


@dataclass(frozen=True)
class ExportedGraph:
    """What `export_graph` wrote: the file, its counts, and the measurements whose noise had a
    range-bearing correlation the BR line cannot carry (written with their marginal sigmas)."""

    path: Path
    poses: int
    landmarks: int
    odometry: int
    measurements: int
    correlated: int


def export_graph(
    run_dir: Path | str, out: Path | str, fmt: str = "g2o", measurements: str = "ekf"
) -> ExportedGraph:
    """Write the pose-landmark graph of the `trunkslam slam` run in `run_dir` (its run log) to
    `out` in format `fmt` ("g2o": GTSAM's readG2o conventions, `experiments.io.g2o`): the
    laser's poses, the odometry and the range-bearing measurements with their noise, the
    associations as run (closures merged), the graph `trunkslam smooth RUN` solves
    (`slam.graph.graph_of_problem`) but for the prior on the start (a solver fixes pose 0).
    measurements: "ekf" or "all", as `trunkslam smooth`'s. The file is written atomically; a
    symlink or other non-regular file at `out` is refused, as is a place inside the run."""
    if fmt not in GRAPH_FORMATS:
        raise DataError(f"--format: expected one of {list(GRAPH_FORMATS)}, got {fmt!r}")
    run_dir, out = check_run_export("export-graph", run_dir, out)
    problem, _ = read_run_log(run_dir, measurements)
    graph, correlated = graph_of_problem(problem)
    write_atomic(out, g2o_text(graph))
    return ExportedGraph(
        path=out,
        poses=int(graph.pose_id.size),
        landmarks=int(graph.landmark_id.size),
        odometry=int(graph.odo_from.size),
        measurements=int(graph.br_pose.size),
        correlated=correlated,
    )


def smooth_graph_file(
    path: Path | str,
    out: Path | str | None = None,
    *,
    method: str = "batch",
    chunk_poses: int = 25,
    polish: bool = False,
    skip: tuple[str, ...] = (),
    edge_noise: str = "information",
) -> dict:
    """Solve the graph file at `path` (`experiments.io.g2o.read_g2o`; skip, edge_noise as
    there) with `slam.smoother.solve_pose_graph` (method, chunk_poses, polish as there; the
    gauge is held by the file's first FIX, else its pose of lowest id) and write the solution to
    `out` (default: PATH's stem + "_smoothed.g2o" beside it): the same graph with the solved
    values. Returns the figures."""
    from slam.smoother import solve_pose_graph

    path = Path(path)
    out = path.with_name(path.stem + "_smoothed.g2o") if out is None else Path(out)
    check_outputs("smooth", inputs=[path], files={"--out": out})
    read = read_g2o(path, skip, edge_noise)
    fixed = read.fixed[0] if read.fixed else None
    r = solve_pose_graph(read.graph, method, chunk_poses, polish=polish, fixed=fixed)
    figures = {
        "graph": str(path),
        "out": str(out),
        "method": r.method,
        "poses": r.n_poses,
        "landmarks": r.n_landmarks,
        "factors": r.n_factors,
        "skipped": dict(read.skipped),
        "chi2": r.chi2,
        "dof": r.dof,
        "chi2_per_dof": r.chi2_per_dof if r.dof > 0 else None,
        "initial_chi2": r.initial_chi2,
        "iterations": r.iterations,
        "seconds": r.seconds,
    }
    write_atomic(out, g2o_text(_with_values(read.graph, r)))
    return figures


def _with_values(g: PoseGraph2D, r) -> PoseGraph2D:
    """g with the solved poses and landmarks as its values."""
    pose = dict(zip(r.pose_id.tolist(), r.pose))
    lm = dict(zip(r.landmark_id.tolist(), r.landmark_xy))
    return PoseGraph2D(
        **{
            **{k: getattr(g, k) for k in g.__dataclass_fields__},
            "pose": np.array([pose[int(i)] for i in g.pose_id]).reshape(-1, 3),
            "landmark_xy": np.array([lm[int(i)] for i in g.landmark_id]).reshape(-1, 2),
        }
    )

"""Simulation with known truth: a 2D world of walls, balusters, pillars, trunks and bushes;
exact ray casting; a SICK sensor model; scans and sequences with per-beam truth labels; a
Cycab-like car driven through a scene (`trajectory`); point-landmark worlds for association and
filter studies (`landmarks`).

    scene = load_scene("pillar_court")
    sensor = sensor_preset("pls200", back_to_back=True)
    rng = np.random.default_rng(0)
    ranges_m, labels = simulate_scan(scene, scene.scan_positions[1], sensor, rng)

Label convention (== `scan_labels` in datasets/FORMAT.md): scene.circles are 0..L-1 (the rows of
`truth_landmarks`), then scene.walls, then scene.bushes; -1 no return; -2 mixed return.
"""

from experiments.sim.landmarks import (
    LandmarkScan,
    LandmarkSimConfig,
    avenue,
    predict_map,
    simulate_landmark_scans,
    vp_scale_scans,
)
from experiments.sim.raycast import raycast, raycast_dense
from experiments.sim.scene import (
    CIRCLE_KINDS,
    MIXED_LABEL,
    NO_RETURN_LABEL,
    WALL_KINDS,
    BushObject,
    CircleObject,
    Scene,
    WallObject,
    list_scenes,
    load_scene,
    make_bush,
    scene_from_dict,
    scenes_dir,
    shape_trunks,
)
from experiments.sim.shapes import TrunkShape
from experiments.sim.simulate import (
    SENSOR_PRESETS,
    SensorModel,
    laser_world_pose,
    sensor_preset,
    simulate_scan,
    simulate_sequence,
    simulate_to_sequence,
)
from experiments.sim.trajectory import CycabParams, simulate_cycab_run

__all__ = [
    "Scene",
    "CircleObject",
    "WallObject",
    "BushObject",
    "load_scene",
    "scene_from_dict",
    "list_scenes",
    "scenes_dir",
    "make_bush",
    "TrunkShape",
    "shape_trunks",
    "NO_RETURN_LABEL",
    "MIXED_LABEL",
    "CIRCLE_KINDS",
    "WALL_KINDS",
    "raycast",
    "raycast_dense",
    "SensorModel",
    "SENSOR_PRESETS",
    "sensor_preset",
    "laser_world_pose",
    "simulate_scan",
    "simulate_sequence",
    "simulate_to_sequence",
    "CycabParams",
    "simulate_cycab_run",
    "LandmarkScan",
    "LandmarkSimConfig",
    "avenue",
    "predict_map",
    "simulate_landmark_scans",
    "vp_scale_scans",
]

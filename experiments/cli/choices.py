"""The choices of the commands' options, as enums typer shows and checks.

The values are written out here (importing the packages would make --help slow);
tests/experiments/test_cli.py checks them against features.METHODS and the rest.
"""

from __future__ import annotations

from enum import StrEnum

from experiments.paper.registry import declared  # light: reads the declarations


class ExtractMethod(StrEnum):
    paper = "paper"
    geometric = "geometric"
    kasa = "kasa"
    taubin = "taubin"
    bailey = "bailey"


class SlamFeatures(StrEnum):
    paper = "paper"
    geometric = "geometric"
    bailey = "bailey"
    detections = "detections"


class Association(StrEnum):
    ihgr = "ihgr"
    ihgr_window = "ihgr-window"
    jcbb = "jcbb"
    nn = "nn"


class SmootherSolver(StrEnum):
    batch = "batch"
    isam2 = "isam2"


class Robust(StrEnum):
    none = "none"
    huber = "huber"
    cauchy = "cauchy"


class SmootherMeasurements(StrEnum):
    ekf = "ekf"
    all = "all"


class EdgeNoise(StrEnum):  # experiments.io.g2o.EDGE_NOISE
    information = "information"
    covariance = "covariance"


class LineTest(StrEnum):
    lrt = "lrt"
    paper = "paper"


class Sensor(StrEnum):
    pls200 = "pls200"
    lms200 = "lms200"


class RosOdometry(StrEnum):  # experiments.io.rosbag.ODOMETRY_SOURCES
    twist = "twist"
    pose = "pose"


# the registered experiments (`experiments.paper.registry`, read without importing them)
ExperimentName = StrEnum("ExperimentName", [(name.replace("-", "_"), name) for name in declared()])


class Study(StrEnum):
    association = "association"
    slam = "slam"
    circles = "circles"


class GraphFormat(StrEnum):  # experiments.pipeline.graph.GRAPH_FORMATS
    g2o = "g2o"


class MapFrame(StrEnum):  # experiments.io.map_export.MAP_FRAMES
    local = "local"
    wgs84 = "wgs84"


class MapFormat(StrEnum):  # experiments.pipeline.export_map.MAP_FORMATS
    geojson = "geojson"
    csv = "csv"

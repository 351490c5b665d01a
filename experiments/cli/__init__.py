"""The `trunkslam` command line: typer only. Each command parses, calls one function, prints.

Heavy imports happen inside the commands so `--help` is instant. `handle_errors` is the one
place that turns the project's own errors (and OSError from files) into `error: ...` and exit
code 1; anything else is a bug and shows its traceback.

- `base`: the app and its groups, the app's own options, `handle_errors`, shared option checks
- `choices`: the options' choices (enums)
- `scans`: extract, convert victoria-park, convert rosbag, simulate, simulate-drive
- `studies`: reproduce, sweep, report
- `runs`: presets, slam, smooth, export-graph, export-map, export-reference
- `bench`: the `bench` commands, made from one table

The command modules are imported here in the order their commands are listed by `--help`.
"""

from __future__ import annotations

# each module adds its commands to the app, in the order `trunkslam --help` lists them
from experiments.cli import scans  # noqa: F401

# isort: split
from experiments.cli import studies  # noqa: F401

# isort: split
from experiments.cli import runs  # noqa: F401

# isort: split
from experiments.cli import bench  # noqa: F401

# isort: split
from experiments.cli.base import app
from experiments.cli.choices import (
    Association,
    EdgeNoise,
    ExperimentName,
    ExtractMethod,
    GraphFormat,
    LineTest,
    MapFormat,
    MapFrame,
    Robust,
    RosOdometry,
    Sensor,
    SlamFeatures,
    SmootherMeasurements,
    SmootherSolver,
    Study,
)

__all__ = [
    "Association",
    "EdgeNoise",
    "ExperimentName",
    "ExtractMethod",
    "GraphFormat",
    "LineTest",
    "MapFormat",
    "MapFrame",
    "Robust",
    "RosOdometry",
    "Sensor",
    "SlamFeatures",
    "SmootherMeasurements",
    "SmootherSolver",
    "Study",
    "app",
]

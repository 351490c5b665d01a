"""The files the package ships: the SLAM presets and the simulator's scenes.

- `experiments/presets/NAME.toml`: what `--config NAME` takes (`trunkslam presets` lists them)
- `experiments/scenes/NAME.json`: what `load_scene(NAME)` and `trunkslam simulate NAME` take

They are package data of `experiments` (pyproject.toml, `[tool.setuptools.package-data]`), read
through `importlib.resources`, so an installed wheel finds them as a checkout does; no path is
built from the repository root. They live inside the package rather than in `datasets/` because
`datasets/` must not be a Python package (an importable `datasets` would shadow HuggingFace's), and
mapping its files into the package at build time would give an editable install and a wheel two
different places to look; `datasets/configs/` and `datasets/scenes/` keep README files that point
here (and the scene schema). This module imports nothing heavy: the CLI's help lists the scenes.
"""

from __future__ import annotations

from importlib.resources import files
from importlib.resources.abc import Traversable

__all__ = [
    "PRESET_SUFFIX",
    "SCENE_SUFFIX",
    "preset_names",
    "presets_dir",
    "scene_names",
    "scenes_dir",
]

PRESET_SUFFIX = ".toml"
SCENE_SUFFIX = ".json"


def presets_dir() -> Traversable:
    """The folder of the bundled presets, `experiments/presets/` wherever the package is."""
    return files("experiments") / "presets"


def scenes_dir() -> Traversable:
    """The folder of the bundled scene files, `experiments/scenes/` wherever the package is."""
    return files("experiments") / "scenes"


def preset_names() -> list[str]:
    """The bundled presets' names (`NAME` of `experiments/presets/NAME.toml`), sorted."""
    return _names(presets_dir(), PRESET_SUFFIX)


def scene_names() -> list[str]:
    """The bundled scenes' names (`NAME` of `experiments/scenes/NAME.json`), sorted."""
    return _names(scenes_dir(), SCENE_SUFFIX)


def _names(folder: Traversable, suffix: str) -> list[str]:
    if not folder.is_dir():
        return []
    return sorted(
        p.name.removesuffix(suffix)
        for p in folder.iterdir()
        if p.name.endswith(suffix) and p.is_file()
    )

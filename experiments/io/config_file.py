"""SLAM configuration files (TOML): read with the standard `tomllib`, written with `tomli_w`.

The file's tables are the sections of `slam.SlamConfig` ([features], [association],
[measurement], [vehicle], [start], [map_policy], [filter]); keys left out keep their defaults.
`SlamConfig.from_dict` refuses unknown keys (suggesting the nearest, or where a key of the
earlier flat format lives now), wrong types and impossible values, and the error names the file
and the key. Presets: experiments/presets/*.toml, package data (`experiments.bundled`), so an
installed wheel has them (`presets`); sweep specifications live apart, in datasets/sweeps/, and
are refused here with a message saying what they are.
"""

from __future__ import annotations

import difflib
import tomllib
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import TYPE_CHECKING

import tomli_w

from experiments.bundled import PRESET_SUFFIX, preset_names, presets_dir
from experiments.errors import ConfigError, DataError
from experiments.io.paths import check_depth, read_text_file

if TYPE_CHECKING:  # `slam` (numpy, numba, scipy) loads when a configuration is read, not for
    from slam import SlamConfig  # `trunkslam presets` or a misspelt preset's name

__all__ = ["config_toml", "load_slam_config", "preset_path", "presets"]


def presets() -> dict[str, str]:
    """Preset name -> its one-line description (the first comment line of its file)."""
    out = {}
    for name in preset_names():
        text = (presets_dir() / f"{name}{PRESET_SUFFIX}").read_text(encoding="utf-8")
        first = next((ln for ln in text.splitlines() if ln.startswith("#")), "# ")
        out[name] = first.lstrip("# ").strip()
    return out


def preset_path(name_or_path: str | Path) -> Path | Traversable:
    """A preset name (experiments/presets/NAME.toml, a `Traversable` of the installed package)
    or a path to a TOML file."""
    p = Path(name_or_path)
    if p.suffix != ".toml" and not p.exists():
        candidate = presets_dir() / f"{name_or_path}{PRESET_SUFFIX}"
        if candidate.is_file():
            return candidate
        close = difflib.get_close_matches(str(name_or_path), preset_names(), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ConfigError(
            f"config {name_or_path!r}: not a file nor a preset (presets: {sorted(presets())}){hint}"
        )
    return p


def load_slam_config(path: str | Path) -> SlamConfig:
    """The `SlamConfig` in a TOML file (or preset name); `DataError`/`ConfigError` naming the
    file and what is wrong."""
    from slam import SlamConfig, SlamError

    path = preset_path(path)
    text = read_text_file(path, "config file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DataError(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise DataError(f"{path}: nested too deeply to be a configuration") from None
    check_depth(data, path)
    try:
        return SlamConfig.from_dict(data)
    except SlamError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def config_toml(cfg: SlamConfig, header: str = "") -> str:
    """The configuration as TOML text (what `load_slam_config` reads back)."""
    lines = "".join(f"# {h}\n" for h in header.splitlines()) if header else ""
    return lines + tomli_w.dumps(cfg.to_dict())

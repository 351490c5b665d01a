"""SLAM configuration files (TOML): read with the standard `tomllib`, written with `tomli_w`.

The file's tables are the sections of `slam.SlamConfig` ([features], [association],
[measurement], [vehicle], [start], [map_policy], [filter]); keys left out keep their defaults.
A preset (experiments/presets/*.toml) stores only what differs from the built-in settings
(`preset_toml`) and is read as that diff over them; the `config.toml` a run writes holds every
setting (`config_toml`), so it reproduces the run whatever the built-in settings become.
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

__all__ = [
    "config_diff",
    "config_toml",
    "load_slam_config",
    "preset_path",
    "preset_toml",
    "presets",
]


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


# Tables written whole when any of their keys differs: a constant noise model is read as its four
# sigmas together (`slam.measurement.NoiseModel`), the associator's parameters as one table.
_WHOLE = ("measurement.constant_noise.", "association.params")


def config_diff(data: dict, base: dict, path: str = "") -> dict:
    """The settings of `data` (a `SlamConfig.to_dict()`) that differ from `base`'s, as a nested
    dict that `SlamConfig.from_dict` reads back to `data`'s configuration."""
    out = {}
    for key, value in data.items():
        where = f"{path}.{key}" if path else key
        if key in base and base[key] == value:
            continue
        whole = where.startswith(_WHOLE[0]) or where == _WHOLE[1]
        if isinstance(value, dict) and isinstance(base.get(key), dict) and not whole:
            value = config_diff(value, base[key], where)
            if not value:
                continue
        out[key] = value
    return out


def preset_toml(cfg: SlamConfig, header: str = "") -> str:
    """The configuration as a preset: only the settings that differ from the built-in ones
    (`SlamConfig()`), which `load_slam_config` reads back to `cfg` (checked here: a setting the
    diff cannot carry, such as None over a built-in value, is an error)."""
    from slam import SlamConfig

    diff = config_diff(cfg.to_dict(), SlamConfig().to_dict())
    if SlamConfig.from_dict(diff) != cfg:
        raise ConfigError("this configuration cannot be written as a diff from the built-in one")
    lines = "".join(f"# {h}\n" for h in header.splitlines()) if header else ""
    return lines + "\n".join(_tables(diff, ""))


def _tables(d: dict, path: str) -> list[str]:
    """Short TOML of a nested dict: a table of plain values (a noise model, a calibration) is
    written inline on its key's line, arrays on one line; blocks separated by blank lines."""
    inline = {k: v for k, v in d.items() if not isinstance(v, dict) or (path and _plain_table(v))}
    lines = [f"[{path}]"] if path and inline else []
    lines += [f"{k} = {_value(v)}" for k, v in inline.items()]
    blocks = ["\n".join(lines) + "\n"] if lines else []
    for k, v in d.items():
        if k not in inline:
            blocks += _tables(v, f"{path}.{k}" if path else k)
    return blocks


def _plain_table(d: dict) -> bool:
    return all(not isinstance(v, dict) for v in d.values())


def _value(v) -> str:
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return tomli_w.dumps({"v": v})[4:-1]

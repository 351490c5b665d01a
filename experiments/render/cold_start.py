"""The compile notice said at once on a cold cache, before numpy, numba and the rest load.

`experiments.render.compiling` says "compiling kernels ..." when numba starts its first compile,
but a command reaches that point only after its imports (numpy, scipy, numba, gtsam, rerun: a
few seconds of silence on a first run, more on a busy machine). `say_if_cold` looks for numba's
cache files of the kernels instead, where numba would put them, and says the notice first thing
when they are not there (the first run after an install, or with an empty `NUMBA_CACHE_DIR`);
`compiling` then does not say it again.

numba is not imported: the cache folder of a source file is found as numba 0.5x-0.6x finds it
(`numba.core.caching`: `$NUMBA_CACHE_DIR/<folder>_<sha1 of the folder's path>` when that is set,
else the `__pycache__` beside the source when it is writable, else the same sub-folder of the
user's cache folder), and an index there (`<module>.<kernel>-<line>.py311.nbi`) counts as
cached. `tests/experiments/test_cold_start.py` checks these folders against numba's own. An
index made from an older source is not told apart: numba then compiles, and says so when it
starts, as before.
"""

from __future__ import annotations

import hashlib
import logging
import os
import sys
from collections.abc import Callable
from pathlib import Path

from experiments.render.compiling import COMPILING_NOTICE, claim_notice

__all__ = ["KERNEL_FILES", "cache_folder", "kernels_cached", "say_if_cold"]

# one source file of each package whose numba kernels every `slam` or `extract` run compiles
KERNEL_FILES = ("features/extract.py", "association/inputs.py", "slam/ekf.py")
_ROOT = Path(os.path.abspath(__file__)).parents[2]  # the folder holding the packages


def _subfolder(source: Path) -> str:
    """numba's `get_suitable_cache_subpath`: the source's folder name and its path's SHA-1."""
    folder = os.path.dirname(os.path.abspath(source))
    return f"{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}"


def _user_cache() -> Path | None:
    """numba's user-wide cache folder (appdirs), on Linux and macOS; None elsewhere."""
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "numba"
    if sys.platform.startswith("linux"):
        return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "numba"
    return None


def _writable(folder: Path) -> bool:
    """Whether numba could make `folder` and write in it."""
    target = folder if folder.exists() else folder.parent
    return os.access(target, os.W_OK | os.X_OK)


def cache_folder(source: Path) -> Path | None:
    """The folder numba caches the kernels of `source` in (None: not one this module knows)."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    if given:
        return Path(given) / _subfolder(source)
    beside = Path(os.path.abspath(source)).parent / "__pycache__"
    if _writable(beside):
        return beside
    user = _user_cache()
    return None if user is None else user / _subfolder(source)


def kernels_cached(files: tuple[str, ...] = KERNEL_FILES) -> bool | None:
    """Whether numba's cache holds an index of each of `files`' kernels (paths from the
    project's root); None when a cache folder is not one this module knows."""
    if os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return True  # nothing will compile
    for name in files:
        folder = cache_folder(_ROOT / name)
        if folder is None:
            return None
        if not any(folder.glob(f"{Path(name).stem}.*.nbi")):
            return False
    return True


def _say(line: str) -> None:
    """A line where the progress lines go before any bar is drawn: the `trunkslam.progress`
    log with -v, else stderr (`experiments.render.progress.Progress.say`)."""
    log = logging.getLogger("trunkslam.progress")
    if log.isEnabledFor(logging.INFO):
        log.info("%s", line)
    else:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()


def say_if_cold(
    files: tuple[str, ...] = KERNEL_FILES, say: Callable[[str], None] | None = None
) -> bool:
    """Say the compile notice now (once per process) when the kernels of `files` are not
    cached; whether it was said."""
    if kernels_cached(files) is not False or not claim_notice():
        return False
    (say or _say)(COMPILING_NOTICE)
    return True

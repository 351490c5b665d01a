"""Where the real datasets live: `TRUNKSLAM_DATA`, else `../shared/datasets` next to the repo
(a checkout only: an installed wheel has no default).

The data are not part of the repository. `TRUNKSLAM_DATA` names the folder holding one
sub-folder per dataset (`victoria_park/`, ...). A relative `TRUNKSLAM_DATA` is taken relative to
the current directory, or failing that to the repository root (CI sets
`TRUNKSLAM_DATA=../shared/datasets` and runs from the repository root, where both agree).
"""

from __future__ import annotations

import os
import stat
from importlib.resources.abc import Traversable
from pathlib import Path

from experiments.errors import DataError, MissingDataError

__all__ = [
    "DATA_ENV",
    "REPO_ROOT",
    "DEFAULT_DATA_ROOT",
    "MAX_DEPTH",
    "MAX_TEXT_BYTES",
    "check_depth",
    "check_input_file",
    "data_root",
    "how_to_get",
    "read_text_file",
    "victoria_park_dir",
]

DATA_ENV = "TRUNKSLAM_DATA"
REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_DATA_ROOT = REPO_ROOT.parent / "shared" / "datasets"

# a checkout (pyproject.toml beside the packages) has a default data folder; an installed wheel
# (the packages in site-packages) has none, and no repository beside it to point to
IN_CHECKOUT = (REPO_ROOT / "pyproject.toml").is_file()

_FILES = (
    "aa3_dr.mat, aa3_gpsx.mat, partial_raw_scans_ss2002/sick.mat, "
    "reference_detections/VictoriaParkSinSincronizar.mat"
)


def how_to_get() -> str:
    """Where the Victoria Park files come from, said for a checkout or for an installed wheel."""
    if IN_CHECKOUT:
        return (
            f"The Victoria Park files ({_FILES}) and where each comes from are listed in "
            "shared/datasets/victoria_park/README.md (the shared data folder beside this "
            "repository, with each file's source repository and sha256). Put them under "
            f"<data>/victoria_park/ and set {DATA_ENV}=<data>."
        )
    return (
        f"The Victoria Park files ({_FILES}) are not part of the trunkslam package: obtain "
        "them as the project's README says (section Data: each file's source and sha256), put "
        f"them under <data>/victoria_park/ and set {DATA_ENV}=<data>."
    )


def data_root() -> Path:
    """The folder holding the datasets (one sub-folder each); `MissingDataError` if there is
    none."""
    value = os.environ.get(DATA_ENV, "").strip()
    if value:
        p = Path(value).expanduser()
        candidates = [p] if p.is_absolute() else [Path.cwd() / p, REPO_ROOT / p]
        for c in candidates:
            if c.is_dir():
                return c.resolve()
        tried = ", ".join(str(c) for c in candidates)
        raise MissingDataError(
            f"{DATA_ENV}={value!r} is not a folder (tried {tried}). {how_to_get()}"
        )
    if IN_CHECKOUT and DEFAULT_DATA_ROOT.is_dir():
        return DEFAULT_DATA_ROOT.resolve()
    if not IN_CHECKOUT:
        raise MissingDataError(f"no dataset folder: {DATA_ENV} is not set. {how_to_get()}")
    raise MissingDataError(
        f"no dataset folder: {DATA_ENV} is not set and the default {DEFAULT_DATA_ROOT} does not "
        f"exist. {how_to_get()}"
    )


def victoria_park_dir() -> Path:
    """`data_root() / "victoria_park"`; `MissingDataError` if it is missing."""
    d = data_root() / "victoria_park"
    if not d.is_dir():
        raise MissingDataError(f"Victoria Park folder not found: {d}. {how_to_get()}")
    return d


MAX_TEXT_BYTES = 1 << 20  # a configuration or sweep file: 1 MiB (the largest preset is 4 kB)


def read_text_file(path: Path | Traversable, what: str, limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of `path`; `DataError` "<what> not found" or naming why it cannot be read.
    At most `limit` bytes are read: a longer file (/dev/zero, /dev/urandom, a log given by
    mistake) is refused naming the limit, before it fills the memory. A FIFO is opened without
    waiting for a writer."""
    try:
        if not isinstance(path, Path):  # a package resource (a preset of an installed wheel)
            data = path.read_bytes()
        else:
            data = _read_at_most(path, limit + 1)
        if len(data) > limit:
            raise DataError(
                f"{path}: larger than {limit // 1024} KiB, too large for a {what} "
                "(experiments.io.paths.MAX_TEXT_BYTES)"
            )
        return data.decode("utf-8")
    except FileNotFoundError:
        raise DataError(f"{what} not found: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: cannot be read ({exc})") from None


def check_input_file(path: Path, what: str) -> Path:
    """`path` is a regular file that can be opened; `DataError` naming it and why not."""
    try:
        st = path.stat()
    except FileNotFoundError:
        if path.is_symlink():
            raise DataError(f"{what} {path}: a symbolic link to nothing") from None
        raise DataError(f"{what} not found: {path}") from None
    except OSError as exc:  # a link to itself (ELOOP), a path through a file (ENOTDIR), ...
        raise DataError(f"{what} {path}: cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file"
        raise DataError(f"{what} {path} is not a file ({kind})")
    return path


def _read_at_most(path: Path, n: int) -> bytes:
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK)
    try:
        os.set_blocking(fd, True)  # (a FIFO with a writer is then read as a file)
        chunks, size = [], 0
        while size < n:
            chunk = os.read(fd, min(n - size, 1 << 16))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


MAX_DEPTH = 64  # tables and lists inside one another in a configuration or sweep file


def check_depth(doc, path, limit: int = MAX_DEPTH) -> None:
    """`DataError` naming the file and the key when the parsed document `doc` (tables and
    lists) is nested more than `limit` deep: the readers walk it recursively. Walked without
    recursion itself."""
    todo = [(doc, ())]
    while todo:
        node, keys = todo.pop()
        if len(keys) > limit:
            named = [str(k) for k in keys if isinstance(k, str)]
            shown = ".".join(named[:6]) + (".…" if len(named) > 6 else "")
            raise DataError(
                f"{path}: {shown or 'a value'}: nested more than {limit} deep "
                "(experiments.io.paths.MAX_DEPTH)"
            )
        if isinstance(node, dict):
            todo += [(v, (*keys, k)) for k, v in node.items()]
        elif isinstance(node, list):
            todo += [(v, (*keys, i)) for i, v in enumerate(node)]

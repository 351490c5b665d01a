"""The sequence file: one run as one `.npz` (datasets/FORMAT.md), read and written.

`save_sequence` writes a `slam.Sequence` atomically; `load_sequence` reads one back and says
what is wrong with a bad file (`DataError`, naming the file and the variable). The run's data
type and its validation live in `slam.sequence`.
"""

from __future__ import annotations

import json
import logging
import lzma
import math
import os
import zipfile
import zlib
from dataclasses import fields
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.writers import write_atomic
from slam import Sequence, SlamError
from slam.sequence import OPTIONAL, REQUIRED

__all__ = ["load_sequence", "save_sequence"]

log = logging.getLogger(__name__)

# what reading a damaged archive raises: zipfile, zlib and the other decompressors a flipped
# compression-method byte selects (NotImplementedError for an unknown method, lzma, bz2's OSError)
_ZIP_ERRORS = (
    OSError,
    ValueError,
    EOFError,
    NotImplementedError,
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
)
_SCALARS = ("scan_angle_min", "scan_angle_increment", "scan_max_range", "scan_n_beams")
_STRINGS = ("vehicle", "name", "det_method")


def save_sequence(seq: Sequence, path: str | os.PathLike) -> Path:
    """Write `seq` to one compressed `.npz` at `path` (exactly that name), atomically.

    The file is written to a temporary file in the same folder and renamed over `path`, so a
    crash never leaves a half-written sequence. Absent optional fields are not stored; `vehicle`
    is stored as a JSON string. Returns the path written.
    """
    if not isinstance(seq, Sequence):
        raise DataError(f"seq: expected a slam.Sequence, got {type(seq).__name__}")
    path = Path(path)
    arrays: dict[str, np.ndarray] = {}
    for f in fields(seq):
        v = getattr(seq, f.name)
        if v is None:
            continue
        if f.name == "vehicle":
            arrays["vehicle"] = np.array(json.dumps(v.to_dict(), sort_keys=True))
        elif f.name == "name":
            arrays["name"] = np.array(v)
        else:
            arrays[f.name] = np.asarray(v)
    return write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays))


def _check_declared_size(npz, k: str, path: Path) -> None:
    """The header of variable k declares no more data than its archive member holds, so a
    corrupt or hostile header (shape (2**33,)) is an error naming the variable, not an attempt
    to allocate tens of gigabytes."""
    try:
        info = npz.zip.getinfo(f"{k}.npy")
        with npz.zip.open(info) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
            header = fh.tell()
    except (KeyError, *_ZIP_ERRORS) as exc:
        raise DataError(f"{path}: variable {k!r} is corrupt or unreadable ({exc})") from None
    if dtype.hasobject:
        return  # pickled objects: np.load refuses them (allow_pickle=False), which says so
    need = math.prod(shape) * dtype.itemsize
    have = info.file_size - header
    if need != have:
        raise DataError(
            f"{path}: variable {k!r} is corrupt: its header declares shape {shape} of {dtype} "
            f"({need} bytes) but it holds {have} bytes"
        )


def load_sequence(path: str | os.PathLike) -> Sequence:
    """Read a sequence file written by `save_sequence` (format: datasets/FORMAT.md).

    Raises `DataError` naming the file and the problem: missing file, not an `.npz` or corrupt,
    a required variable missing, wrong shapes, unsorted times, inconsistent variables. Optional
    variables that are absent become None; unknown variables are ignored with a logged warning.
    """
    path = Path(path)
    if not path.exists():
        raise DataError(f"sequence file not found: {path}")
    if not path.is_file():
        raise DataError(f"sequence file {path} is not a file")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise DataError(f"{path}: cannot be read ({exc})") from None
    if magic.startswith(b"\x93NUMPY"):
        raise DataError(f"{path}: is a single .npy array, not an .npz sequence file")
    if not magic.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # zip: member, or empty
        raise DataError(f"{path}: not a readable .npz sequence file (not a zip archive)")
    try:
        npz = np.load(path, allow_pickle=False)
    except _ZIP_ERRORS as exc:
        raise DataError(f"{path}: not a readable .npz sequence file ({exc})") from None
    values: dict[str, object] = {}
    with npz:
        keys = set(npz.files)
        missing = [k for k in REQUIRED if k not in keys]
        if missing:
            raise DataError(
                f"{path}: missing required variable(s) {missing} (has: {sorted(keys)}); "
                "see datasets/FORMAT.md"
            )
        unknown = sorted(keys - set(REQUIRED) - set(OPTIONAL))
        if unknown:
            log.warning("%s: ignoring unknown variable(s) %s", path, unknown)
        for k in (*REQUIRED, *OPTIONAL):
            if k not in keys:
                continue
            _check_declared_size(npz, k, path)
            try:
                a = npz[k]
            except _ZIP_ERRORS as exc:
                raise DataError(
                    f"{path}: variable {k!r} is corrupt or unreadable ({exc})"
                ) from None
            if k in _STRINGS:
                if a.dtype.kind != "U" or a.ndim != 0:
                    raise DataError(
                        f"{path}: variable {k!r} must be a string, got dtype {a.dtype} "
                        f"shape {a.shape}"
                    )
                values[k] = str(a)
            elif k in _SCALARS:
                if a.size != 1:
                    raise DataError(
                        f"{path}: variable {k!r} must be one number, got shape {a.shape}"
                    )
                values[k] = a
            else:
                values[k] = a
    try:
        return Sequence(**values)
    except SlamError as exc:
        raise DataError(f"{path}: {exc}") from None

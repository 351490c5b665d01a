"""Reading an `.npz` format against its schema: the sequence file and the run log.

An `.npz` is a zip archive of `.npy` members. `read_npz` opens it itself (not through `np.load`)
so that nothing of a member is used before the member is known good:

- the file: a regular file (a folder, a FIFO, a link to itself are named), a zip archive with
  nothing after its end (appended bytes mean a damaged or concatenated file), no encrypted
  member;
- each variable the schema knows: its header read first, its dtype of the declared kind
  (`Var.kind`: numbers, integers or a string; complex, datetime, boolean, byte-string and object
  arrays are refused, whatever the values), its dimensions those of the schema, with each named
  dimension (N scans, ...) the same in every variable that has it, and its data exactly the
  size the header declares (a member with bytes after its data, or cut short, is corrupt);
- memory: the arrays' declared sizes together must fit in the memory this process may use
  (`MemoryBudget`), so that a hostile header or a huge scan is an error naming the size, not a
  `MemoryError` half-way through the work.

Values (finite, in range, sorted) are the data types' business (`slam.Sequence`,
`slam.smoother.Problem`), which the readers build next. Errors are `DataError`s naming the file
and the variable.
"""

from __future__ import annotations

import logging
import math
import resource
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.io.paths import check_input_file  # noqa: F401  (here before; light there)

__all__ = [
    "PARSE_ERRORS",
    "Var",
    "available_memory",
    "check_input_file",
    "check_method_name",
    "read_npz",
]

log = logging.getLogger(__name__)

# What parsing a damaged archive or `.npy` header can raise is open-ended: zipfile, zlib and the
# decompressors a flipped compression-method byte selects (NotImplementedError, lzma, bz2's
# OSError), struct.error, and numpy's header parser (SyntaxError, tokenize.TokenError on a
# mangled header dict). Every exception while parsing the untrusted bytes means a corrupt file,
# so the parsing steps catch `Exception` (Ctrl-C, a BaseException, still propagates; memory is
# budgeted before any array is read, `_check_memory`).
PARSE_ERRORS = (Exception,)
KINDS = {"float": "fiu", "int": "iu", "str": "U"}  # numpy dtype kinds each kind accepts
_KIND_WORDS = {"float": "numbers", "int": "integers", "str": "a string"}
# bytes of memory an array of n bytes in the file may take while it is read and used: the file's
# array, its float64 copy in the data type, and the work on it (a conservative factor)
MEMORY_FACTOR = 3


@dataclass(frozen=True)
class Var:
    """One variable of an `.npz` format: kind "float" (any real numbers, stored as float64 by
    the data type), "int" or "str" (a 0-d unicode string); shape: its dimensions, each a number
    or a name shared with the other variables that have it ("N": scans); () for a scalar (a
    1-element array of any shape is taken for one number); required: the file must have it."""

    kind: str
    shape: tuple = ()
    required: bool = False

    def describe(self) -> str:
        dims = "(" + ", ".join(str(d) for d in self.shape) + ("," if len(self.shape) == 1 else "")
        return (
            f"{_KIND_WORDS[self.kind]} of shape {dims})"
            if self.shape
            else ("a string" if self.kind == "str" else f"one {_KIND_WORDS[self.kind][:-1]}")
        )


def check_method_name(path, key: str, value: str) -> str:
    """A method's name read from a file (a sequence's `det_method`, a run log's `features` and
    `association`): words, not blank and not a number written as text ("3.0", "nan": the
    number a writer put there, turned into a string). `DataError` naming the file and the key."""
    if not value.strip():
        raise DataError(f"{path}: {key}: an empty method name")
    try:
        float(value)
    except ValueError:
        return value
    raise DataError(f"{path}: {key}: {value!r} is a number, not the name of a method")


def available_memory() -> int | None:
    """Bytes this process may still allocate: the smaller of the system's available memory
    (/proc/meminfo MemAvailable) and what its address-space limit (`ulimit -v`) leaves; None
    when neither is known."""
    limits = []
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    limits.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        used = 0
        try:
            with open("/proc/self/status") as fh:
                for line in fh:
                    if line.startswith("VmSize:"):
                        used = int(line.split()[1]) * 1024
        except (OSError, ValueError, IndexError):
            pass
        limits.append(max(soft - used, 0))
    return min(limits) if limits else None


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB" if n >= 1e8 else f"{n / 1e6:.3g} MB"


def _trailing_bytes(path: Path) -> int:
    """Bytes after the end of the zip archive (its end-of-central-directory record and comment)."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        fh.seek(max(0, size - 65_557))
        tail = fh.read()
    i = tail.rfind(b"PK\x05\x06")
    if i < 0 or i + 22 > len(tail):
        return 0  # zipfile says what is wrong
    comment = int.from_bytes(tail[i + 20 : i + 22], "little")
    return len(tail) - (i + 22 + comment)


def _header(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, name: str):
    """(shape, fortran_order, dtype, header bytes) of a member, read without its data."""
    try:
        with zf.open(info) as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            return shape, fortran, dtype, fh.tell()
    except PARSE_ERRORS as exc:
        raise DataError(f"{path}: variable {name!r} is corrupt or unreadable ({exc})") from None


def _symbolic(shape: tuple) -> str:
    return "(" + ", ".join(str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"


def _check_kind(path: Path, name: str, var: Var, dtype: np.dtype, shape: tuple, *, what) -> None:
    if dtype.hasobject:
        raise DataError(
            f"{path}: variable {name!r} is corrupt or unreadable (it holds pickled Python "
            f"objects, which a {what} never does)"
        )
    ok = dtype.fields is None and dtype.kind in KINDS[var.kind]
    if ok and var.kind == "str":
        ok = len(shape) == 0
    if not ok:
        raise DataError(
            f"{path}: variable {name!r} must be {var.describe()}, got dtype {dtype} of shape "
            f"{shape}"
        )


def _check_dims(
    path: Path, schema: Mapping[str, Var], shapes: dict[str, tuple], across: bool
) -> None:
    """Each variable's shape against the schema's; with `across`, each named dimension the same
    in every variable that has it."""
    seen: dict[str, tuple[int, str]] = {}
    for name, var in schema.items():
        if name not in shapes:
            continue
        shape = shapes[name]
        if not var.shape:  # one value: any shape with one element
            if var.kind != "str" and math.prod(shape) != 1:
                raise DataError(
                    f"{path}: variable {name!r} must be {var.describe()}, got shape {shape}"
                )
            continue
        fixed = all(not isinstance(d, int) or n == d for d, n in zip(var.shape, shape))
        if len(shape) != len(var.shape) or not fixed:
            raise DataError(f"{path}: {name}: expected shape {_symbolic(var.shape)}, got {shape}")
        for d, n in zip(var.shape, shape):
            if isinstance(d, int):
                continue
            if across and d in seen and seen[d][0] != n:
                size, owner = seen[d]
                raise DataError(
                    f"{path}: {name}: expected shape {_symbolic(var.shape)} with {d} = {size} "
                    f"as in {owner}, got {shape}"
                )
            seen.setdefault(d, (n, name))


def read_npz(
    path: Path | str,
    schema: Mapping[str, Var],
    what: str,
    *,
    across: bool = True,
    signature: tuple[str, str] | None = None,
    logger: logging.Logger | None = None,
) -> dict[str, np.ndarray]:
    """The variables of the `.npz` at `path` that `schema` names, checked (module doc). `what`
    names the format in messages ("sequence file"); across: check that each named dimension is
    the same in every variable (False: the data type checks it, with its own words);
    signature: (variable, text) that marks the format (the run log's `format`), checked first,
    so that a file of another kind is named as such before its missing variables are listed.
    Unknown variables and members that are not arrays are ignored with a warning on `logger`."""
    logger = logger or log
    path = check_input_file(Path(path), what)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        raise DataError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if magic.startswith(b"\x93NUMPY"):
        raise DataError(f"{path}: is a single .npy array, not an .npz {what}")
    if not magic.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # zip: a member, or empty
        raise DataError(f"{path}: not a readable .npz {what} (not a zip archive)")
    try:
        zf = zipfile.ZipFile(path)
    except PARSE_ERRORS as exc:
        raise DataError(f"{path}: not a readable .npz {what} ({exc})") from None
    with zf:
        extra = _trailing_bytes(path)
        if extra:
            raise DataError(
                f"{path}: {extra} byte(s) after the end of the zip archive (a damaged or "
                "concatenated file)"
            )
        members = _members(zf, path, logger)
        if signature is not None:
            _check_signature(zf, members, path, schema, (what, *signature))
        missing = [k for k, v in schema.items() if v.required and k not in members]
        if missing:
            raise DataError(
                f"{path}: missing required variable(s) {missing} (has: {sorted(members)})"
            )
        unknown = sorted(set(members) - set(schema))
        if unknown:
            logger.warning("%s: ignoring unknown variable(s) %s", path, unknown)
        headers = {}
        for name in schema:
            if name in members:
                shape, fortran, dtype, size = _header(zf, members[name], path, name)
                _check_kind(path, name, schema[name], dtype, shape, what=what)
                need = math.prod(shape) * dtype.itemsize
                have = members[name].file_size - size
                if need != have:
                    raise DataError(
                        f"{path}: variable {name!r} is corrupt: its header declares shape "
                        f"{shape} of {dtype} ({need} bytes) but it holds {have} bytes"
                    )
                headers[name] = (shape, dtype, need)
        _check_dims(path, schema, {k: h[0] for k, h in headers.items()}, across)
        _check_memory(path, headers)
        out = {}
        for name in headers:
            try:
                with zf.open(members[name]) as fh:
                    out[name] = np.lib.format.read_array(fh, allow_pickle=False)
            except PARSE_ERRORS as exc:
                raise DataError(
                    f"{path}: variable {name!r} is corrupt or unreadable ({exc})"
                ) from None
    return out


def _members(zf: zipfile.ZipFile, path: Path, logger) -> dict[str, zipfile.ZipInfo]:
    """{variable: its member} of the archive; members that are not arrays ignored (a warning),
    an encrypted one refused."""
    members = {}
    for info in zf.infolist():
        if not info.filename.endswith(".npy"):
            logger.warning("%s: ignoring member %r (not an array)", path, info.filename)
            continue
        name = info.filename[:-4]
        if info.flag_bits & 0x1:
            raise DataError(f"{path}: variable {name!r} is encrypted (password-protected)")
        members[name] = info
    return members


def _check_signature(zf: zipfile.ZipFile, members, path: Path, schema, sig) -> None:
    """The variable that marks the format holds its text (sig: (what, variable, text));
    `DataError` "not a WHAT" otherwise."""
    what, name, text = sig
    if name not in members:
        raise DataError(f"{path}: not a {what} (no {name!r} variable saying {text!r})")
    shape, _, dtype, size = _header(zf, members[name], path, name)
    _check_kind(path, name, schema[name], dtype, shape, what=what)
    if math.prod(shape) * dtype.itemsize > 4096:
        raise DataError(f"{path}: {name}: not a {what} ({text!r} expected)")
    try:
        with zf.open(members[name]) as fh:
            value = str(np.lib.format.read_array(fh, allow_pickle=False))
    except PARSE_ERRORS as exc:
        raise DataError(f"{path}: variable {name!r} is corrupt or unreadable ({exc})") from None
    if value != text:
        raise DataError(f"{path}: {name}: not a {what} ({text!r} expected, got {value[:40]!r})")


def _check_memory(path: Path, headers: dict) -> None:
    total = sum(h[2] for h in headers.values()) * MEMORY_FACTOR
    have = available_memory()
    if have is not None and total > have:
        name, (shape, dtype, n) = max(headers.items(), key=lambda kv: kv[1][2])
        raise DataError(
            f"{path}: reading it needs about {_gb(total)} of memory ({name!r} alone is "
            f"{shape} of {dtype}, {_gb(n)}), more than the {_gb(have)} this process may use"
        )

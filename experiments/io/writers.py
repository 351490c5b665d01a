"""Writing results: the features JSON of `trunkslam extract`, tidy result tables (CSV, and the
Markdown table pivoted from the same records), atomic files and atomic result folders.

Every result is written so that an interruption (Ctrl-C, a full disk, a crash) leaves either the
old complete result or the new complete one, never a mix:
- `write_atomic`: one file, through a temporary file in the same folder and a rename;
- `atomic_folder`: a set of files (a `trunkslam reproduce` or `trunkslam slam` output folder),
  written into a temporary folder beside the target and swapped into place only when complete.
What a command may write where (its outputs against its inputs, result folders and their
manifests, the folder lock) is `experiments.io.outputs`' part. A write error (a full disk)
is a `WriteError` naming the output; inside an `atomic_folder`, named by its place in the
target folder.
"""

from __future__ import annotations

import contextlib
import csv
import ctypes
import ctypes.util
import errno
import io
import json
import math
import os
import shutil
import signal
import stat
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from experiments.errors import DataError, WriteError
from features.types import Features

__all__ = [
    "FEATURES_SCHEMA",
    "atomic_folder",
    "dumps_json",
    "csv_value",
    "features_to_dict",
    "file_kind",
    "format_cell",
    "json_types",
    "markdown_table",
    "parse_value",
    "pivot",
    "pivot_cells",
    "read_tidy_csv",
    "refuse_non_regular",
    "tidy_csv",
    "tidy_markdown",
    "tidy_table",
    "write_atomic",
    "write_tidy_table",
]

FEATURES_SCHEMA = "trunkslam.features/1"


def _f(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _nums(a, decimals: int):
    """An array as nested lists of rounded floats, non-finite values as None (JSON null)."""
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        r = np.round(a, decimals)
    r = np.where(np.isfinite(r), r, a)  # rounding a huge value overflows: keep it as it is
    out = r.astype(object)
    out[~np.isfinite(r)] = None
    return out.tolist()


def features_to_dict(f: Features, scan_index: int) -> dict:
    """One scan's features as plain JSON types (laser frame, metres, radians)."""
    return {
        "scan": scan_index,
        "stamp_s": _f(f.stamp_s),
        "method": f.method,
        "circles": [
            {
                "center_xy": [_f(p[0]), _f(p[1])],
                "radius_m": _f(p[2]),
                "cov": _nums(c, 12),
                "beams": [int(b[0]), int(b[1])],
                "rms_residual_m": _f(s),
            }
            for p, c, b, s in zip(f.circle_params, f.circle_cov, f.circle_beams, f.circle_rms_m)
        ],
        "lines": [
            {
                "alpha_rad": _f(p[0]),
                "rho_m": _f(p[1]),
                "cov": _nums(c, 12),
                "endpoints_xy": _nums(e, 6),
                "beams": [int(b[0]), int(b[1])],
                "rms_residual_m": _f(s),
            }
            for p, c, e, b, s in zip(
                f.line_params, f.line_cov, f.line_endpoints, f.line_beams, f.line_rms_m
            )
        ],
        "edges": [
            {"point_xy": [_f(p[0]), _f(p[1])], "cov": _nums(c, 12), "beam": int(b)}
            for p, c, b in zip(f.edge_xy, f.edge_cov, f.edge_beam)
        ],
        "clutter": [
            {"beams": [int(b[0]), int(b[1])]}
            for b, k in zip(f.segment_beams, f.segment_kind)
            if k == 0
        ],
    }


def write_atomic(path: Path | str, data: str | bytes | Callable[[BinaryIO], object]) -> Path:
    """Write `data` (text, bytes, or a function writing to a binary file) to `path` atomically:
    into a temporary file in the same folder, flushed to disk, made readable by all (0644), then
    renamed over `path`; a crash never leaves a half-written file. The folder must exist, and
    `path` must not be anything but a regular file (`DataError` for a folder, a symlink, a FIFO,
    a device: the rename would replace it)."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise DataError(f"cannot write {path}: folder {folder} does not exist")
    refuse_non_regular(path, "output")
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise WriteError(path, exc) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            if callable(data):
                data(fh)
            else:
                fh.write(data.encode() if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes files owner-only
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, WriteError):
            raise
        raise WriteError(path, exc) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    interruption_point("file-written")
    return path


def interruption_point(name: str) -> None:
    """Fault injection for the interruption tests: when the environment variable
    `TRUNKSLAM_INTERRUPT_AT` names this point, the process sends itself SIGINT here (a real
    Ctrl-C at a known moment instead of a race with a timer), or the signal named by
    `TRUNKSLAM_INTERRUPT_SIGNAL` (SIGTERM, SIGHUP). No effect otherwise."""
    if os.environ.get("TRUNKSLAM_INTERRUPT_AT") == name:
        sig = os.environ.get("TRUNKSLAM_INTERRUPT_SIGNAL", "SIGINT")
        signal.raise_signal(getattr(signal, sig, signal.SIGINT))


def file_kind(mode: int) -> str:
    """What a path's `st_mode` (from `os.lstat`) says it is, in words ("a symbolic link")."""
    if stat.S_ISREG(mode):
        return "a regular file"
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "an unknown kind of file"


def refuse_non_regular(path: Path, option: str, *, folder: bool = False) -> None:
    """`DataError` naming `option` and `path` when it exists and is not a regular file (a
    symlink, folder, FIFO, device: renaming over it would replace it); folder: when it exists
    and is not a folder (an output folder's check)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise DataError(f"{option} {path}: cannot be checked ({exc})") from None
    if folder and not stat.S_ISDIR(mode):
        raise DataError(
            f"{option} {path}: exists and is {file_kind(mode)}, not a folder; refusing to "
            "replace it"
        )
    if not folder and not stat.S_ISREG(mode):
        raise DataError(
            f"{option} {path}: exists and is {file_kind(mode)}, not a regular file; refusing to "
            "replace it (choose another path)"
        )


_RENAME_EXCHANGE = 2  # linux/fs.h
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False where unsupported."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _remove_stale(target: Path) -> None:
    """Temporary folders of `target` left by runs that were killed (their process is gone)."""
    for p in target.parent.glob(f".{target.name}.partial-*"):
        try:
            pid = int(p.name.rsplit(".partial-", 1)[1].split("-")[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(p, ignore_errors=True)
        except (ValueError, IndexError, OSError):
            continue


@contextlib.contextmanager
def atomic_folder(target: Path | str) -> Iterator[Path]:
    """Write a set of files as one: yields a new temporary folder beside `target`
    (`.NAME.partial-PID-XXXX`); when the block ends without an exception, the folder is made
    readable by all and put in `target`'s place (a previous `target` is swapped out in one step
    where the system allows it, Linux renameat2, else by two renames, and then deleted). On an
    exception or interruption the temporary folder is deleted and `target` is left as it was.
    Check `target` with `check_output_folder` first: it is replaced as a whole."""
    target = Path(target)
    parent = target.parent
    if not parent.is_dir():
        raise DataError(f"cannot write {target}: folder {parent} does not exist")
    _remove_stale(target)
    prefix = f".{target.name}.partial-{os.getpid()}-"
    staging = None
    try:  # the folder is made inside: an interruption while making it still cleans up
        staging = Path(tempfile.mkdtemp(dir=parent, prefix=prefix))
        yield staging
        os.chmod(staging, 0o755)  # mkdtemp makes folders owner-only
        _fsync_dir(staging)
        _swap_into_place(staging, target)
    except BaseException as exc:
        # interrupted inside mkdtemp: the folder may exist without its name having come back
        for p in [staging] if staging is not None else parent.glob(prefix + "*"):
            shutil.rmtree(p, ignore_errors=True)
        if isinstance(exc, OSError):
            raise _named_in(target, staging, exc) from None
        raise
    _fsync_dir(parent)


def _named_in(target: Path, staging: Path | None, exc: OSError) -> OSError:
    """A write error in the temporary folder, named by the file's place in `target` (the path
    the user gave), or by `target` itself."""
    name = Path(exc.filename) if isinstance(exc.filename, str) else None
    if staging is None or name is None or not name.is_relative_to(staging):
        return exc  # not a file of the set (an input, say): as it was
    rel = name.relative_to(staging)
    return WriteError(target if rel == Path(".") else target / rel, exc)


def _swap_into_place(staging: Path, target: Path) -> None:
    """Put the complete folder `staging` at `target`; delete what was there."""
    try:
        os.rename(staging, target)  # no target, or an empty folder: replaced in one step
        return
    except OSError as exc:
        if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY):
            raise
    if _exchange(staging, target):
        shutil.rmtree(staging, ignore_errors=True)  # staging now holds the old set
        return
    old = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{target.name}.old-"))
    os.rename(target, old / target.name)
    os.rename(staging, target)
    shutil.rmtree(old, ignore_errors=True)


def _cell(v) -> str:
    if isinstance(v, float):
        if not math.isfinite(v):
            return "n/a"
        return f"{v:.4g}" if abs(v) < 1e4 else f"{v:.3e}"
    return str(v)


def format_cell(v) -> str:
    """A value as a Markdown table cell: floats to 4 significant digits, a value that is not
    there (None, NaN, inf) as "n/a", anything else as its text."""
    if v is None:
        return "n/a"
    if isinstance(v, (np.integer, np.floating)):
        v = v.item()
    return _cell(v)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(_cell(v) for v in r) + " |" for r in rows]
    return "\n".join(out) + "\n"


# ---- tidy tables --------------------------------------------------------------------------------
#
# A result table is a list of records (dicts), one per observation. Its CSV holds them as they
# are (one row each, every field a column); its Markdown table is a pivot of them. See the
# docs/result-tables.md for the two layouts the experiments use.

PIVOT_MARK = "<!-- pivot of "


def csv_value(v) -> str:
    """A value as a CSV cell: floats at full precision (repr), a missing value (None, NaN) as
    an empty cell, inf as "inf"; anything else as its text."""
    if v is None:
        return ""
    if isinstance(v, (np.integer, np.floating, np.bool_)):
        v = v.item()
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    return str(v)


def parse_value(text: str):
    """A CSV cell read back: "" as NaN, integers as int, other numbers as float, else the text."""
    if text == "":
        return math.nan
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


def read_tidy_csv(path: Path | str) -> list[dict]:
    """The records of a result CSV (`write_tidy_table`), values parsed with `parse_value`."""
    with open(path, newline="") as fh:
        return [{k: parse_value(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def _key_part(v):
    if isinstance(v, (np.integer, np.floating, np.bool_)):
        v = v.item()
    if v is None or (isinstance(v, float) and math.isnan(v)):
        raise ValueError("an identifier of a tidy record is missing (None or NaN)")
    return v


def pivot(
    records: Sequence[dict],
    index: Sequence[str],
    columns: Sequence[str] = (),
    values: str | Sequence[str] = "value",
) -> tuple[list[tuple], list[tuple], dict[tuple, object]]:
    """The wide view of tidy records, in plain Python.

    A row per distinct value of the `index` fields, a column per distinct value of the
    `columns` fields (and per name in `values` when there are several: value name outer,
    column values inner), in order of first appearance. Returns (row keys, column keys as
    (*column values, value name), cells {(row key, column key): value}); a combination no
    record has is absent from cells. `ValueError` when two records give the same cell (the
    records are not one per observation) or an identifier is missing."""
    names = [values] if isinstance(values, str) else list(values)
    rows: dict[tuple, None] = {}
    cols: dict[tuple, None] = {}
    cells: dict[tuple, object] = {}
    for r in records:
        rk = tuple(_key_part(r[f]) for f in index)
        ck = tuple(_key_part(r[f]) for f in columns)
        rows.setdefault(rk)
        cols.setdefault(ck)
        for name in names:
            if name not in r:
                continue
            key = (rk, (*ck, name))
            if key in cells:
                raise ValueError(
                    f"pivot: two records for {dict(zip(index, rk))} {dict(zip(columns, ck))} "
                    f"{name}: the records are not one per observation"
                )
            cells[key] = r[name]
    col_keys = [(*ck, name) for name in names for ck in cols]
    col_keys = [c for c in col_keys if any((rk, c) in cells for rk in rows)]
    return list(rows), col_keys, cells


def pivot_cells(records, index, columns=(), values="value") -> list[list[str]]:
    """The Markdown cells of the pivot (`pivot`): per row, the index values, then the cells
    (`format_cell`; "" where no record has that combination)."""
    return _formatted(*pivot(records, index, columns, values))


def _formatted(row_keys, col_keys, cells) -> list[list[str]]:
    """`pivot`'s output as Markdown cells (see `pivot_cells`)."""
    return [
        [format_cell(v) for v in rk]
        + [format_cell(cells[(rk, ck)]) if (rk, ck) in cells else "" for ck in col_keys]
        for rk in row_keys
    ]


def _label(key: tuple, labels: dict, several_values: bool, columns: Sequence[str]) -> str:
    parts = key if (several_values or not columns) else key[:-1]
    for k in (key, parts):
        if k in labels:
            return labels[k]
    text = " ".join(str(p) for p in parts)
    return labels.get(text, text)


def tidy_markdown(
    records: Sequence[dict],
    index: Sequence[str],
    columns: Sequence[str] = (),
    values: str | Sequence[str] = "value",
    labels: dict | None = None,
    source: str = "",
) -> str:
    """The Markdown table of tidy records: their pivot (`pivot`), headed by `labels` (an index
    field's name, a column key's text or tuple -> header text; default the text itself), after
    a comment naming the CSV `source` and the pivot so that it can be checked against it."""
    labels = dict(labels or {})
    names = [values] if isinstance(values, str) else list(values)
    row_keys, col_keys, cells = pivot(records, index, columns, values)
    header = [labels.get(f, f) for f in index]
    header += [_label(ck, labels, len(names) > 1, columns) for ck in col_keys]
    spec = {"index": list(index), "columns": list(columns), "values": names}
    mark = f"{PIVOT_MARK}{source}: {json.dumps(spec)} -->\n" if source else ""
    return (
        mark
        + markdown_table(header, [])
        + "".join("| " + " | ".join(r) + " |\n" for r in _formatted(row_keys, col_keys, cells))
    )


def tidy_csv(records: Sequence[dict], fields: Sequence[str] | None = None) -> str:
    """The CSV text of tidy records: one row each; columns `fields` (default: every field, in
    order of first appearance); a field a record lacks is an empty cell."""
    if fields is None:
        fields = list(dict.fromkeys(k for r in records for k in r))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(fields)
    for r in records:
        w.writerow([csv_value(r.get(f)) for f in fields])
    return buf.getvalue()


def tidy_table(
    name: str,
    records: Sequence[dict],
    index: Sequence[str],
    columns: Sequence[str] = (),
    values: str | Sequence[str] = "value",
    *,
    labels: dict | None = None,
    title: str = "",
    notes: str = "",
    parts: Sequence[tuple[str, Sequence[str]]] = (),
) -> tuple[str, str]:
    """The texts `write_tidy_table` writes, (Markdown, CSV), for the table `name` (its file
    stem: the Markdown's pivots name `name`.csv as their source). See `write_tidy_table`."""
    fields = list(dict.fromkeys(k for r in records for k in r))
    names = [values] if isinstance(values, str) else list(values)
    shown = {*index, *columns, *names}
    if set(fields) - shown:
        raise ValueError(f"write_tidy_table: fields {sorted(set(fields) - shown)} not in the pivot")
    split = [v for _, vs in parts for v in vs]
    if parts and sorted(split) != sorted(names):
        raise ValueError(
            "write_tidy_table: parts must hold every value once; missing "
            f"{sorted(set(names) - set(split))}, unknown or repeated "
            f"{sorted({v for v in split if v not in names or split.count(v) > 1})}"
        )
    records = [{f: r.get(f) for f in fields} for r in records]
    source = name + ".csv"
    md = f"# {title}\n\n" if title else ""
    if parts:
        md += "\n".join(
            f"## {heading}\n\n"
            + tidy_markdown(records, index, columns, list(vs), labels, source=source)
            for heading, vs in parts
        )
    else:
        md += tidy_markdown(records, index, columns, values, labels, source=source)
    if notes:
        md += "\n" + notes.strip() + "\n"
    return md, tidy_csv(records, fields)


def write_tidy_table(
    stem: Path,
    records: Sequence[dict],
    index: Sequence[str],
    columns: Sequence[str] = (),
    values: str | Sequence[str] = "value",
    *,
    labels: dict | None = None,
    title: str = "",
    notes: str = "",
    parts: Sequence[tuple[str, Sequence[str]]] = (),
) -> list[Path]:
    """Write tidy records as `stem`.csv (one row per record, every field a column, numbers at
    full precision, missing values empty) and `stem`.md (title, the pivot of the same records
    by `tidy_markdown`, notes); returns both paths. Every field must appear in the pivot
    (`index`, `columns` or `values`), so that the Markdown table shows all of the CSV.

    parts: [(heading, value names)] splits the Markdown into narrow tables, one per part (a
    `##` heading, then the pivot of the same records by `index` and `columns` with those
    values, marked as a pivot of the CSV like a whole table): a table too wide to read, shown
    by concern. Together the parts hold every one of `values`, each once. The CSV is the same
    either way."""
    stem = Path(stem)
    md, text = tidy_table(
        stem.name,
        records,
        index,
        columns,
        values,
        labels=labels,
        title=title,
        notes=notes,
        parts=parts,
    )
    return [write_atomic(stem.with_suffix(".md"), md), write_atomic(stem.with_suffix(".csv"), text)]


def dumps_json(obj) -> str:
    """`obj` as indented JSON; NaN and inf are refused (convert them first, `json_types`)."""
    return json.dumps(obj, indent=1, allow_nan=False)


def json_types(obj):
    """Dicts, lists, tuples and numpy scalars as plain JSON types; non-finite floats as strings."""
    if isinstance(obj, dict):
        return {k: json_types(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_types(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    return obj

"""Where a command may write: its outputs checked against its inputs, result folders held by one
command at a time and listed in their manifest.

- `check_outputs`: the one check every command makes before any work. Every output path (a
  file, a folder replaced as a whole, a folder written into) is compared, after resolving links
  (`os.path.realpath`), and by inode for hard links, with every input the command reads
  (sequence, configuration, features file, scene, sweep spec, data folder) and with the scene
  and preset files the package ships: an output that is an input, a folder holding an input, an
  output inside an input folder, a package file, or two outputs on one path are refused with a
  `DataError` naming the option and both paths. Then each path's own checks:
- `check_output_file`: absent or a regular file (not a symlink, a FIFO, a device), in a folder
  that exists;
- `check_output_folder`: a folder replaced as a whole (`writers.atomic_folder`) must be absent,
  empty, or an earlier output of the same command every file of which its `manifest.json`
  lists (`write_manifest`); a file it does not list is named and the folder kept.
- `lock_folder`: an advisory lock (`fcntl.flock`) on `.NAME.lock` beside a result folder, held
  by a command from its check to its last write: a second command on the folder is refused at
  once, naming the holder. The kernel drops the lock of a killed process. The lock file is
  opened without following links (`O_NOFOLLOW`): one that is a symbolic link, a hard link, a
  FIFO or a folder is refused, naming it, and what it points to is left as it was.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import sys
from collections.abc import Iterable, Iterator, Mapping
from importlib.resources.abc import Traversable
from pathlib import Path

from experiments.bundled import presets_dir, scenes_dir
from experiments.errors import DataError
from experiments.io.writers import dumps_json, file_kind, refuse_non_regular, write_atomic

try:
    import fcntl
except ImportError:  # pragma: no cover  (not POSIX: result folders are not locked)
    fcntl = None

__all__ = [
    "MANIFEST",
    "add_to_manifest",
    "check_output_file",
    "check_output_folder",
    "check_run_export",
    "check_outputs",
    "check_path_text",
    "lock_folder",
    "read_manifest",
    "write_manifest",
]

MANIFEST = "manifest.json"

PathLike = Path | str | None


def _real(p: Path | str) -> Path:
    return Path(os.path.realpath(p))


def _inode(p: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(p)
    except OSError:
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def _inside(path: Path, folder: Path) -> bool:
    """True when the resolved `path` is `folder` or lies under it (both resolved)."""
    return path == folder or path.is_relative_to(folder)


def _package_folders() -> list[tuple[str, Path]]:
    """The package's data folders (scenes, presets) as real paths (where they are files)."""
    out = []
    for what, folder in (("scenes", scenes_dir()), ("presets", presets_dir())):
        if os.path.isdir(str(folder)):  # a zip import has no paths to write over
            out.append((what, _real(str(folder))))
    return out


def _package_inodes(folders: list[tuple[str, Path]]) -> dict[tuple[int, int], Path]:
    found = {}
    for _, folder in folders:
        with contextlib.suppress(OSError):
            for p in folder.iterdir():
                ino = _inode(p)
                if ino is not None:
                    found[ino] = p
    return found


class _Output:
    def __init__(self, option: str, path: Path | str, kind: str) -> None:
        self.option = option
        self.path = Path(path)
        self.kind = kind  # "file", "folder" (replaced whole) or "into" (written into)
        self.real = _real(self.path)

    def refuse(self, why: str) -> DataError:
        return DataError(f"{self.option} {self.path}: {why}")


def check_outputs(
    command: str,
    inputs: Iterable[PathLike | Traversable] = (),
    files: Mapping[str, PathLike] | None = None,
    folders: Mapping[str, PathLike] | None = None,
    into: Mapping[str, PathLike] | None = None,
) -> None:
    """Refuse, before any work, an output of `trunkslam COMMAND` that would overwrite or
    replace something it reads or the package's own files (see the module doc).

    inputs: the files and folders the command reads (None and paths that do not exist, such as
        a preset's or a scene's name, are skipped; a folder's files are all inputs);
    files: {option: path} of the output files (None: not asked for);
    folders: {option: path} of the output folders replaced as a whole (`check_output_folder`:
        absent, empty, or an earlier output of COMMAND);
    into: {option: path} of folders the command writes files into without replacing them.
    A file inside an output folder is allowed (it becomes part of the set: slam's --rerun).
    `DataError` naming the option, the path and what it would overwrite."""
    for option, p in [*(files or {}).items(), *(folders or {}).items(), *(into or {}).items()]:
        if p is not None:
            check_path_text(p, option)
    inputs = list(inputs)
    for i in inputs:
        if isinstance(i, (str, bytes, os.PathLike)):  # (not a package resource)
            check_path_text(i, "input")
    outs = [_Output(o, p, "file") for o, p in (files or {}).items() if p is not None]
    outs += [_Output(o, p, "folder") for o, p in (folders or {}).items() if p is not None]
    outs += [_Output(o, p, "into") for o, p in (into or {}).items() if p is not None]
    ins = [(Path(str(i)), _real(str(i))) for i in inputs if i is not None]
    ins = [(i, real) for i, real in ins if os.path.lexists(i)]
    package = _package_folders()
    package_files = _package_inodes(package)
    for k, out in enumerate(outs):
        _against_inputs(out, ins)
        _against_package(out, package, package_files)
        for other in outs[:k]:
            _against_output(out, other)
    for out in outs:
        in_set = any(o.kind == "folder" and _inside(out.real, o.real) for o in outs if o is not out)
        if out.kind == "file":
            if not in_set:  # (one inside a folder goes into its new set)
                check_output_file(out.path, out.option)
        elif out.kind == "folder":
            _check_unless_held(out, command)
        else:
            _refuse_non_folder(out.path, out.option)


_VERB = {"file": "overwrite", "folder": "replace", "into": "write into"}


def _against_inputs(out: _Output, ins: list[tuple[Path, Path]]) -> None:
    ino = _inode(out.real)
    for inp, real in ins:
        if out.real == real or (ino is not None and ino == _inode(real)):
            raise out.refuse(
                f"is an input of this command ({inp}); refusing to {_VERB[out.kind]} it"
            )
        if out.kind != "file" and _inside(real, out.real):
            raise out.refuse(
                f"holds the input {inp}; refusing to {_VERB[out.kind]} it (choose another folder)"
            )
        if os.path.isdir(real) and _inside(out.real, real):
            raise out.refuse(
                f"is inside the input folder {inp}, which this command only reads; choose a "
                "place outside it"
            )


def _against_package(out: _Output, package, package_files) -> None:
    for what, folder in package:
        if _inside(out.real, folder):
            raise out.refuse(
                f"is in the trunkslam package's {what} folder ({folder}), whose files are read, "
                "never written; choose another place"
            )
        if out.kind != "file" and _inside(folder, out.real):
            raise out.refuse(
                f"holds the trunkslam package's {what} folder ({folder}); refusing to "
                f"{_VERB[out.kind]} it"
            )
    ino = _inode(out.real)
    if ino is not None and ino in package_files:
        raise out.refuse(
            f"is another name of the trunkslam package's file {package_files[ino]}; refusing "
            "to overwrite it"
        )


def _against_output(out: _Output, other: _Output) -> None:
    """Two outputs: never one path; nested only as a file inside a folder (part of its set)."""
    if out.real == other.real:
        raise out.refuse(f"is also {other.option}; give each output its own path")
    for inner, outer in ((out, other), (other, out)):
        if _inside(inner.real, outer.real):
            if inner.kind == "file":
                return
            raise out.refuse(
                f"lies in or around {other.option} {other.path}; give each output its own place"
            )


def _check_unless_held(out: _Output, command: str) -> None:
    """`check_output_folder`, made before the folder is held: a command holding it meanwhile
    may be writing it (its temporary files are not yet in its manifest), so a refusal is
    first checked against the lock: "in use" when held, the check made again when the holder
    has just finished, the refusal itself otherwise."""
    for attempt in range(3):
        try:
            check_output_folder(out.path, out.option, command)
            return
        except DataError:
            _refuse_if_held(out.real, out.path, out.option)
            if attempt == 2:
                raise


def _lock_file(real: Path) -> Path:
    """The lock file of the result folder at the resolved path `real`: `.NAME.lock` beside it."""
    return real.parent / f".{real.name}.lock"


def _refuse_if_held(real: Path, folder: Path, option: str) -> None:
    """The "in use" `DataError` of `lock_folder` when another process holds `folder` now."""
    lock = _lock_file(real)
    if fcntl is None or str(lock) in _held:
        return
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return  # no lock file (or not one: lock_folder names it): nobody holds it
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        raise _in_use(folder, option, _holder(fd)) from None
    finally:
        os.close(fd)  # (closing it drops a lock this probe took)


def _in_use(folder: Path, option: str, holder: str) -> DataError:
    return DataError(
        f"{option} {folder}: in use by another trunkslam command ({holder}); try again "
        "when it has finished, or choose another folder"
    )


def _refuse_non_folder(path: Path, option: str) -> None:
    refuse_non_regular(path, option, folder=True)


def check_path_text(path: Path | str, option: str) -> None:
    """`DataError` naming `option` when `path` holds a NUL byte (no file has such a name) or
    bytes that are not UTF-8 (the path is written into the results: summary.json, manifests,
    the configuration's header, which are UTF-8)."""
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if "\0" in text:
        raise DataError(f"{option} {text!r}: a path cannot hold a NUL byte")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(text).decode("utf-8", errors="backslashreplace")
        raise DataError(
            f"{option} {shown}: the path's bytes are not UTF-8, which the results that name it "
            "(summary.json, manifest.json) are written in; rename it"
        ) from None


def check_output_file(path: Path | str, option: str) -> Path:
    """An output file path's own checks: absent or a regular file (not a symlink, FIFO or
    device: a rename would replace it), in a folder that exists. `DataError` naming the option
    and the path otherwise. The inputs are `check_outputs`' part."""
    check_path_text(path, option)
    path = Path(path)
    refuse_non_regular(path, option)
    if not path.parent.is_dir():
        raise DataError(f"{option} {path}: folder {path.parent} does not exist")
    return path


def check_run_export(command: str, run_dir: Path | str, out: Path | str) -> tuple[Path, Path]:
    """(run_dir, out) as paths, for a command that writes one file `out` from the output folder
    of `trunkslam slam` `run_dir` (export-graph, export-map): `DataError` when run_dir is not a
    folder, or when `out` fails `check_outputs` (an input, a place inside the run, a link)."""
    run_dir, out = Path(run_dir), Path(out)
    if not run_dir.is_dir():
        raise DataError(f"{run_dir}: not a folder (expected the output folder of trunkslam slam)")
    check_outputs(command, inputs=[run_dir], files={"--out": out})
    return run_dir, out


def read_manifest(folder: Path | str) -> dict:
    """The manifest.json of a result folder: {"command": "trunkslam NAME", "outputs": [files
    beside it, relative paths], ...}. `DataError` naming it when it is missing or malformed. A
    `trunkslam reproduce` manifest written before manifests named their command counts as
    reproduce's."""
    path = Path(folder) / MANIFEST
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path}: not found") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"{path}: cannot be read ({exc})") from None
    if not isinstance(doc, dict):
        raise DataError(f"{path}: expected a JSON object, got {type(doc).__name__}")
    outputs = doc.get("outputs")
    if not isinstance(outputs, list) or not all(isinstance(o, str) for o in outputs):
        raise DataError(f"{path}: 'outputs' must be a list of file names")
    if "command" not in doc and "experiments" in doc:
        doc["command"] = "trunkslam reproduce"
    if not isinstance(doc.get("command"), str):
        raise DataError(f"{path}: 'command' must name the command that wrote the folder")
    return doc


def _entries(folder: Path) -> list[str]:
    """Every entry under folder (files, links, folders; not following links), relative."""
    found = []
    for root, dirs, names in os.walk(folder):
        rel = Path(root).relative_to(folder)
        found += [str(rel / n) for n in dirs + names]
    return sorted(found)


def check_output_folder(path: Path | str, option: str, command: str) -> Path:
    """An output folder's own checks. It is replaced as a whole (`atomic_folder`), so it must be
    absent, an empty folder, or an earlier output of `trunkslam COMMAND` every file of which
    its manifest.json lists; not a symlink, a file, a FIFO. `DataError` naming the option, the
    path and the reason (the first files it would lose that trunkslam did not write)."""
    check_path_text(path, option)
    path = Path(path)
    _refuse_non_folder(path, option)
    if not path.exists():
        return path
    try:
        entries = _entries(path)
    except OSError as exc:
        raise DataError(f"{option} {path}: cannot be read ({exc})") from None
    if not entries:
        return path
    whole = "it would be replaced as a whole, so choose another folder or empty it"
    if MANIFEST not in entries:
        raise DataError(
            f"{option} {path}: exists, is not empty and has no {MANIFEST} listing the files "
            f"trunkslam wrote there (not an output of trunkslam {command}, or one written "
            f"before outputs had a manifest); {whole}"
        )
    try:
        manifest = read_manifest(path)
    except DataError as exc:
        raise DataError(f"{option} {path}: its {exc}; {whole}") from None
    wanted = f"trunkslam {command}"
    if manifest["command"] != wanted:
        raise DataError(
            f"{option} {path}: is an output of `{manifest['command']}`, not of `{wanted}`; "
            "refusing to replace it (choose another folder)"
        )
    ours = {MANIFEST}
    for name in manifest["outputs"]:
        p = Path(name)
        ours.add(str(p))
        ours.update(str(q) for q in p.parents if str(q) != ".")
    foreign = [e for e in entries if e not in ours]
    if foreign:
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        shown = ", ".join(foreign[:3]) + more
        raise DataError(
            f"{option} {path}: holds {shown}, not written by trunkslam (not in its {MANIFEST}); "
            "refusing to replace the folder and lose it (move it away or choose another folder)"
        )
    return path


def _files(folder: Path) -> list[str]:
    names = (str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir())
    return sorted(n for n in names if n != MANIFEST)


def write_manifest(stage: Path | str, command: str, **extra) -> Path:
    """Write `stage`/manifest.json: the command (`trunkslam COMMAND`), `extra` fields, and every
    file under `stage` (relative paths). The last file of a result set: with it, the set is
    complete, and `check_output_folder` knows every file as trunkslam's."""
    stage = Path(stage)
    doc = {"command": f"trunkslam {command}", **extra, "outputs": _files(stage)}
    return write_atomic(stage / MANIFEST, dumps_json(doc))


def add_to_manifest(folder: Path | str, names: Iterable[str]) -> None:
    """List more files (about to be written into `folder` by a command holding its lock) in its
    manifest, written again atomically. No manifest (an output of an older trunkslam): nothing
    to do."""
    folder = Path(folder)
    if not (folder / MANIFEST).exists():
        return
    doc = read_manifest(folder)
    doc["outputs"] = sorted(set(doc["outputs"]) | set(names))
    write_atomic(folder / MANIFEST, dumps_json(doc))


# ---- one command per result folder --------------------------------------------------------------

_held: dict[str, list] = {}  # lock file -> [descriptor, depth]: this process's locks


def _holder(fd: int) -> str:
    with contextlib.suppress(OSError):
        text = os.pread(fd, 512, 0).decode(errors="replace").strip()
        if text:
            return text
    return "pid unknown"


# a lock file is opened without following a link (O_NOFOLLOW) and without waiting on a FIFO
_LOCK_FLAGS = os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK


def _open_lock(lock: Path, folder: Path, option: str) -> int:
    """The lock file `lock`, opened (created when missing) for writing without following a
    link; `DataError` naming it when it is anything but a regular file of one name (a symbolic
    link, a FIFO, a folder, a device, or a hard link to another file: writing the holder's pid
    into it would overwrite what it points to)."""
    refuse = f"{option} {folder}: its lock file {lock}"
    try:
        fd = os.open(lock, _LOCK_FLAGS, 0o644)
    except OSError as exc:
        try:
            kind = file_kind(os.lstat(lock).st_mode)
        except OSError:
            kind = None
        if kind is not None and kind != "a regular file":
            raise DataError(_not_a_lock(refuse, kind)) from None
        raise DataError(f"{refuse} cannot be opened ({exc.strerror})") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:
        os.close(fd)
        kind = file_kind(st.st_mode) if not stat.S_ISREG(st.st_mode) else "a hard link"
        raise DataError(_not_a_lock(refuse, kind))
    return fd


def _not_a_lock(refuse: str, kind: str) -> str:
    return (
        f"{refuse} exists and is {kind}, not a regular file of its own; refusing to write "
        "through it (remove it: trunkslam makes it again)"
    )


def _acquire(lock: Path, folder: Path, option: str) -> int:
    for _ in range(100):
        fd = _open_lock(lock, folder, option)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            raise _in_use(folder, option, holder) from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:  # not a file its last holder removed while we waited for it
            argv = " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])[:300]
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"pid {os.getpid()}: {argv}\n".encode(), 0)
            return fd
        os.close(fd)
    raise DataError(f"{option} {folder}: its lock {lock} keeps changing; try again")


@contextlib.contextmanager
def lock_folder(folder: Path | str, option: str = "--out") -> Iterator[None]:
    """Hold the result folder `folder` for this command: an exclusive advisory lock
    (`fcntl.flock`) on `.NAME.lock` beside it (its parent folder is created if missing), taken
    at once or refused (`DataError` naming the folder and the holder's pid and command line).
    Held again by the same process (slam --smooth) it nests. Released, and the lock file
    removed, when the block ends; the kernel releases it when the process dies (kill -9), and
    the next command takes over the file left behind. Every trunkslam command that writes a
    result folder holds it (slam, smooth, reproduce, sweep, export-reference), so two of them
    never interleave on one folder."""
    real = _real(folder)
    if fcntl is None:  # pragma: no cover
        yield
        return
    real.parent.mkdir(parents=True, exist_ok=True)
    lock = _lock_file(real)
    key = str(lock)
    if key in _held:
        _held[key][1] += 1
        try:
            yield
        finally:
            _held[key][1] -= 1
        return
    fd = _acquire(lock, Path(folder), option)
    _held[key] = [fd, 1]
    try:
        yield
    finally:
        del _held[key]
        with contextlib.suppress(OSError):
            os.unlink(lock)  # still holding it: a command waiting on this file retries
        os.close(fd)

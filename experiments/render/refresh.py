"""`trunkslam report`: refresh the documentation's results snapshot from result folders, as one
set, never pruning what the sources do not hold.

The snapshot (`docs/results/`) holds the tables, figures and manifests of `trunkslam reproduce`
folders (and the benchmark tables of `make bench`), and a record of its own, `snapshot.json`:
every file of the snapshot and where it came from (the source folder, its commit, date and
experiments). `refresh_snapshot`

1. reads and checks everything before it touches anything: each source is a `trunkslam
   reproduce` folder (its manifest.json; the first one's becomes the snapshot's, a later one's
   `manifest_<folder>.json`) or a folder of benchmark tables (`bench_*.md`, as `make bench`
   writes them; its other files are skipped), every CSV parses row by row, and
   the columns the README's glance reads as numbers hold numbers (`GLANCE_COLUMNS`); the
   snapshot folder is absent, empty, or ours (every file in it listed by its `snapshot.json`:
   a file it does not list is named and nothing is touched); the README has its glance block;
2. builds the new snapshot in a staging folder beside it: the files the sources hold replace
   theirs, every other file of the snapshot (the calibrations, the benchmarks, experiments the
   sources did not run) is kept, with its origin;
3. renders every documentation page's macros and the README's glance against the staged
   snapshot: a macro that would not resolve refuses the refresh, naming the page and the macro;
4. puts the staged folder in the snapshot's place in one step (`writers.atomic_folder`), then
   the README (written beside it before the swap, renamed into place after).

A refusal or an error before step 4 leaves the snapshot and the README as they were, byte for
byte. The outcome (`Refresh`) says what was replaced, added and kept, and which kept files
could not be refreshed: files from a run whose every experiment the sources ran again, without
writing that file (left over from an older version of an experiment).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from experiments.errors import DataError
from experiments.io.outputs import MANIFEST, read_manifest
from experiments.io.writers import atomic_folder, dumps_json, read_tidy_csv, refuse_non_regular
from experiments.render.report import (
    GLANCE_BEGIN,
    GLANCE_END,
    MACRO,
    ReportError,
    Snapshot,
    glance_table,
    render_macros,
)

__all__ = [
    "GLANCE_COLUMNS",
    "KEPT_SUFFIXES",
    "RECORD",
    "Refresh",
    "check_glance_columns",
    "refresh_snapshot",
    "snapshot_record",
]

# what a snapshot keeps of a results folder: tables, figures, the run's records (not recordings)
KEPT_SUFFIXES = (".csv", ".md", ".png", ".json", ".toml")
RECORD = "snapshot.json"  # the snapshot's own record: its files and where each came from
MAX_FILE_BYTES = 64 * 2**20  # a table or figure of a results folder is far smaller
MAX_PAGES = 2000

# The columns the README's glance reads as numbers, by table: "number" (an empty cell, NaN,
# prints n/a) or "count" (an integer, or empty). Text there would make the glance meaningless.
GLANCE_COLUMNS: dict[str, dict[str, str]] = {
    "table1_ce": {"value": "number"},
    "table2_re": {"value": "number"},
    "table3": {"value": "number"},
    "table4": {"value": "number"},
    "consistency": {"nees_in_bounds": "number"},
    "victoria_park": {
        "scans": "count",
        "landmarks": "count",
        "one_tree_pairs": "count",
        "rmse_m": "number",
        "rmse_vouched_m": "number",
        "rmse_rfs_m": "number",
        "rmse_rfs_low_m": "number",
        "precision_1m": "number",
        "reference_trees_1m": "number",
        "false_detection_rate": "number",
    },
    "loop_closure": {
        "runs": "count",
        "returns_2_5_m": "count",
        "with_closure_2_5_m": "count",
        "closed_2_5_m": "count",
        "false_closures": "count",
        "nees_inside_after_return": "number",
    },
    "smoother": {"rmse_vouched_m": "number"},
}


@dataclass
class Refresh:
    """What `refresh_snapshot` did (or, refused, would have done: nothing was changed then).

    replaced / added: the snapshot's files the sources held (names);
    kept: {origin: names} of the snapshot's files the sources did not hold, by where they came
        from ("results_cal2: victoria-park-calibration at c4a999a5, 2026-11-26 09:20 UTC");
    stale: the kept files that could not be refreshed (their run's experiments all ran again
        in the sources, none wrote them);
    skipped: entries of the sources not copied (links, folders, other kinds of file);
    readme: "rewritten", "unchanged" or "" (no README)."""

    replaced: list[str] = field(default_factory=list)
    added: list[str] = field(default_factory=list)
    kept: dict[str, list[str]] = field(default_factory=dict)
    stale: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    readme: str = ""


def refresh_snapshot(
    sources: Sequence[Path | str],
    dest: Path | str,
    *,
    pages: Path | str | None = None,
    readme: Path | str | None = None,
) -> Refresh:
    """Refresh the snapshot folder `dest` from the result folders `sources` (see the module
    doc): check every input, stage the new snapshot, check the pages under `pages` (every .md
    below it outside `dest`; None: none) and the README's glance against it, then swap it in
    and rewrite `readme`'s glance block (None: no README). `ReportError` (or `DataError`)
    naming the problem, with nothing changed, when a check fails."""
    dest = Path(dest)
    incoming, origins, outcome = _read_sources([Path(s) for s in sources])
    record = _read_snapshot(dest)
    readme_text = _read_readme(Path(readme)) if readme is not None else None
    page_files = _pages(Path(pages), dest) if pages is not None else []
    _plan(outcome, incoming, origins, record)
    staged_readme = None
    try:
        with atomic_folder(dest) as stage:
            new_record = _stage(stage, dest, incoming, origins, record)
            check_glance_columns(stage, where=lambda name: incoming.get(name, (dest / name,))[0])
            snapshot = Snapshot(stage)
            _check_pages(page_files, snapshot, quick=_quick(incoming))
            if readme_text is not None:
                new_text = _readme_with_glance(Path(readme), readme_text, snapshot)
                outcome.readme = "unchanged" if new_text == readme_text else "rewritten"
                if new_text != readme_text:
                    staged_readme = _stage_file(Path(readme), new_text)
            (stage / RECORD).write_text(dumps_json(new_record))
        if staged_readme is not None:
            os.replace(staged_readme, readme)
            staged_readme = None
    finally:
        if staged_readme is not None:
            with contextlib.suppress(OSError):
                staged_readme.unlink()
    return outcome


# ---- 1. the inputs, read and checked before anything is written ---------------------------------


def _read_sources(sources: list[Path]) -> tuple[dict, dict, Refresh]:
    """{name: (source path, bytes, source label)} of every file to copy, {source label:
    origin} and the outcome with the skipped entries; `ReportError` for a source that is not
    a results folder."""
    if not sources:
        raise ReportError("report: no results folder given")
    incoming: dict[str, tuple[Path, bytes, str]] = {}
    origins: dict[str, dict] = {}
    outcome = Refresh()
    for src in sources:
        _check_source_folder(src)
        manifest = _source_manifest(src)
        label = _label(src, origins)
        origins[label] = _origin(label, manifest)
        main = manifest is not None and MANIFEST not in incoming
        files = 0
        for f in sorted(src.iterdir(), key=lambda p: p.name):
            if f.suffix not in KEPT_SUFFIXES or f.name == RECORD:
                continue
            if f.is_symlink() or not f.is_file() or (manifest is None and not _bench(f.name)):
                outcome.skipped.append(str(f))
                continue
            name = f.name if (f.name != MANIFEST or main) else f"manifest_{label}.json"
            incoming[name] = (f, _read_source_file(f), label)
            files += 1
        if not files:
            what = "tables, figures or manifests" if manifest else "benchmark tables (bench_*.md)"
            raise ReportError(f"{src}: holds no {what} to report")
    for name, (path, data, _) in incoming.items():
        if name.endswith(".csv"):
            _check_csv(path, data)
    return incoming, origins, outcome


def _check_source_folder(src: Path) -> None:
    if src.is_symlink():
        raise ReportError(f"{src}: is a link; give the results folder itself")
    if not src.exists():
        raise ReportError(f"{src}: no such folder")
    if not src.is_dir():
        raise ReportError(f"{src}: not a folder (give a `trunkslam reproduce --out` folder)")


def _bench(name: str) -> bool:
    return name.startswith("bench_") and name.endswith(".md")


def _source_manifest(src: Path) -> dict | None:
    """The source's manifest (a `trunkslam reproduce` folder's); None for a folder of
    benchmark tables (no manifest.json, some bench_*.md)."""
    if not (src / MANIFEST).exists():
        if not any(_bench(p.name) for p in src.iterdir()):
            raise ReportError(
                f"{src}: not a `trunkslam reproduce` folder (no {MANIFEST}) nor a folder of "
                "benchmark tables (no bench_*.md)"
            )
        return None
    try:
        manifest = read_manifest(src)
    except DataError as exc:
        raise ReportError(f"{src}: {exc}") from None
    if manifest["command"] != "trunkslam reproduce":
        raise ReportError(
            f"{src}: an output of `{manifest['command']}`, not of `trunkslam reproduce`; report "
            "takes reproduce folders and folders of benchmark tables"
        )
    return manifest


def _label(src: Path, origins: dict) -> str:
    label = src.resolve().name or "results"
    n = 2
    while label in origins:
        label, n = f"{src.resolve().name}_{n}", n + 1
    return label


def _origin(label: str, manifest: dict | None) -> dict:
    """Where files came from: the source folder's name, and its run when it has a manifest."""
    if manifest is None:
        return {"source": label}
    return {
        "source": label,
        "commit": str(manifest.get("git_commit") or "unknown"),
        "finished": str(manifest.get("finished") or "unknown"),
        "experiments": [str(e) for e in manifest.get("experiments", [])],
    }


def _read_source_file(f: Path) -> bytes:
    try:
        size = f.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ReportError(
                f"{f}: {size} bytes, more than a table or figure of a results folder holds "
                f"({MAX_FILE_BYTES} at most)"
            )
        return f.read_bytes()
    except OSError as exc:
        raise ReportError(f"{f}: cannot be read ({exc.strerror or exc})") from None


def _check_csv(path: Path, data: bytes) -> None:
    """Every row of a result CSV has its header's cells (a ragged or binary table is named)."""
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ReportError(f"{path}: not a text table ({exc.reason} at byte {exc.start})") from None
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise ReportError(f"{path}: not a CSV table ({exc})") from None
    if not rows or not rows[0]:
        raise ReportError(f"{path}: an empty table (no header line)")
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(rows[0]):
            raise ReportError(f"{path} line {i}: {len(row)} cells, the header has {len(rows[0])}")


def check_glance_columns(folder: Path, where=lambda name: name) -> None:
    """The columns of `GLANCE_COLUMNS` in the tables of `folder` that have them hold numbers
    (a count: a whole number); `ReportError` naming the file (`where(name)`), row, column and
    cell otherwise."""
    for table, columns in GLANCE_COLUMNS.items():
        name = f"{table}.csv"
        if not (folder / name).is_file():
            continue
        records = read_tidy_csv(folder / name)
        for i, r in enumerate(records, start=2):
            for column, kind in columns.items():
                if column not in r:
                    continue
                v = r[column]
                bad = isinstance(v, str) or (
                    kind == "count" and isinstance(v, float) and math.isfinite(v) and v != int(v)
                )
                if bad:
                    want = "a whole number" if kind == "count" else "a number"
                    raise ReportError(
                        f"{where(name)} line {i}, column {column}: {str(v)[:40]!r} is not "
                        f"{want} (the README's results at a glance reads it)"
                    )


def _read_snapshot(dest: Path) -> dict:
    """The snapshot's record ({"origins": {label: origin}, "files": {name: label}}) after
    checking that `dest` is ours: absent, empty, or every entry listed by its record.
    `ReportError` naming a foreign file."""
    refuse_non_regular(dest, "--docs", folder=True)
    if not dest.exists():
        return {"origins": {}, "files": {}}
    entries = sorted(os.listdir(dest))
    if not entries:
        return {"origins": {}, "files": {}}
    if RECORD not in entries:
        raise ReportError(
            f"--docs {dest}: holds {entries[0]}"
            + (f" and {len(entries) - 1} more" if len(entries) > 1 else "")
            + f" but no {RECORD}: not a snapshot `trunkslam report` made; refusing to write "
            "into it (give an empty or new folder, or the project's docs/results)"
        )
    try:
        record = json.loads((dest / RECORD).read_text(encoding="utf-8"))
        origins, files = record["origins"], record["files"]
        if not isinstance(origins, dict) or not all(isinstance(v, dict) for v in origins.values()):
            raise TypeError("'origins' must map each source to what it was")
        if not isinstance(files, dict) or not all(v in origins for v in files.values()):
            raise TypeError("'files' must map each file to one of 'origins'")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise ReportError(f"--docs {dest}: its {RECORD} cannot be read ({exc})") from None
    for e in entries:
        if e == RECORD:
            continue
        if e not in files or (dest / e).is_symlink() or not (dest / e).is_file():
            raise ReportError(
                f"--docs {dest}: holds {e}, which `trunkslam report` did not write (not in its "
                f"{RECORD}); refusing to touch the folder (move {e} away)"
            )
    return record


def _read_readme(readme: Path) -> str:
    refuse_non_regular(readme, "--readme")
    if not readme.is_file():
        raise ReportError(f"--readme {readme}: no such file")
    try:
        text = readme.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ReportError(f"--readme {readme}: cannot be read ({exc})") from None
    if GLANCE_BEGIN not in text or GLANCE_END not in text.split(GLANCE_BEGIN, 1)[1]:
        raise ReportError(
            f"--readme {readme}: no results-at-a-glance block (the lines {GLANCE_BEGIN!r} and "
            f"{GLANCE_END!r})"
        )
    return text


def _pages(pages: Path, dest: Path) -> list[Path]:
    """The Markdown pages under `pages` whose macros the snapshot must answer (not `dest`'s)."""
    if not pages.is_dir():
        raise ReportError(f"--pages {pages}: no such folder (give '' to check no pages)")
    snap = dest.resolve()
    found = sorted(p for p in pages.rglob("*.md") if snap not in p.resolve().parents)
    if len(found) > MAX_PAGES:
        raise ReportError(f"--pages {pages}: more than {MAX_PAGES} pages; give the docs folder")
    return found


# ---- 2. the new snapshot -------------------------------------------------------------------------


def _plan(outcome: Refresh, incoming: dict, origins: dict, record: dict) -> None:
    """Fill `outcome`: replaced, added, kept (by origin) and stale."""
    ran = {e for o in origins.values() for e in o.get("experiments", [])}
    for name in sorted(incoming):
        (outcome.replaced if name in record["files"] else outcome.added).append(name)
    for name, label in sorted(record["files"].items()):
        if name in incoming:
            continue
        origin = record["origins"][label]
        outcome.kept.setdefault(_describe(origin), []).append(name)
        made_by = set(origin.get("experiments", []))
        if made_by and made_by <= ran:
            outcome.stale.append(name)


def _describe(origin: dict) -> str:
    source = Path(str(origin.get("source", "unknown"))).name
    if "experiments" not in origin:
        return source
    exps = ", ".join(origin["experiments"]) or "no experiment"
    return f"{source}: {exps} at {str(origin.get('commit'))[:8]}, {origin.get('finished')}"


def _stage(stage: Path, dest: Path, incoming: dict, origins: dict, record: dict) -> dict:
    """Write the new snapshot's files into `stage`; its record (a kept file's origin under a
    new label when a source of this refresh took its old one)."""
    files, new_origins = {}, dict(origins)
    for name, label in record["files"].items():
        if name in incoming:
            continue
        (stage / name).write_bytes((dest / name).read_bytes())
        origin, kept_label, n = record["origins"][label], label, 2
        while new_origins.get(kept_label, origin) != origin:
            kept_label, n = f"{label} ({n})", n + 1
        new_origins[kept_label] = origin
        files[name] = kept_label
    for name, (_, data, label) in incoming.items():
        (stage / name).write_bytes(data)
        files[name] = label
    used = set(files.values())
    return {
        "command": "trunkslam report",
        "origins": {k: v for k, v in sorted(new_origins.items()) if k in used},
        "files": dict(sorted(files.items())),
    }


def _stage_file(path: Path, text: str) -> Path:
    """`text` written beside `path` under a temporary name, to be renamed into place."""
    tmp = path.with_name(f".{path.name}.report-{os.getpid()}")
    with open(tmp, "x", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    return tmp


# ---- 3. the pages and the README against the staged snapshot --------------------------------


def _quick(incoming: dict) -> bool:
    """Whether the first source is a `reproduce --quick` run (its manifest says so)."""
    entry = incoming.get(MANIFEST)
    with contextlib.suppress(ValueError, UnicodeDecodeError, AttributeError):
        return bool(json.loads(entry[1].decode("utf-8")).get("quick")) if entry else False
    return False


def _check_pages(pages: Iterable[Path], snapshot: Snapshot, quick: bool = False) -> None:
    for page in pages:
        try:
            text = page.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ReportError(f"page {page}: cannot be read ({exc})") from None
        if not MACRO.search(text):
            continue
        try:
            render_macros(text, snapshot, str(page))
        except ReportError as exc:
            hint = (
                "; these are `reproduce --quick` results, and the pages quote the full runs"
                if quick
                else ""
            )
            raise ReportError(
                f"refused: with these results a macro would not resolve: {exc} (nothing was "
                f"changed; report a results folder that holds it, or mend the page{hint})"
            ) from None


def _readme_with_glance(readme: Path, text: str, snapshot: Snapshot) -> str:
    try:
        table = glance_table(snapshot)
    except ReportError as exc:
        raise ReportError(
            f"refused: the README's results at a glance cannot be made from these results: "
            f"{exc} (nothing was changed)"
        ) from None
    head, rest = text.split(GLANCE_BEGIN, 1)
    _, tail = rest.split(GLANCE_END, 1)
    return _run_time(head + GLANCE_BEGIN + "\n" + table + GLANCE_END + tail, snapshot)


RUN_TIME = re.compile(r"about\s+[0-9.]+\s+(?:s|min|h)\s+on\s+(\w+)\s+cores")
_NUMBERS = {1: "one", 2: "two", 3: "three", 4: "four", 8: "eight"}


def _run_time(text: str, snapshot: Snapshot) -> str:
    """The README's time of `make reproduce` ("about 7.6 min on two cores") set to the
    snapshot's: its manifest's experiments' times added, on its machine's cores."""
    if not RUN_TIME.search(text):
        return text
    try:
        seconds = snapshot.duration()
        cores = int(str(snapshot.manifest().get("machine", "")).split(" cores")[0].split()[-1])
    except (ReportError, ValueError, IndexError, TypeError):
        return text  # a manifest without the run's times or its machine: left as it was
    words = f"about {seconds} on {_NUMBERS.get(cores, str(cores))} cores"
    return RUN_TIME.sub(words, text, count=1)


def snapshot_record(folder: Path | str) -> dict:
    """The record (`snapshot.json`) of an existing snapshot folder: each file's origin, from
    the newest manifest in the folder that lists it (a manifest itself: its own run; a file no
    manifest lists: its name's kind, "bench" for the benchmark tables). For a snapshot made
    before report kept a record."""
    folder = Path(folder)
    manifests = []
    for m in sorted(folder.glob("manifest*.json")):
        doc = json.loads(m.read_text(encoding="utf-8"))
        label = "results" if m.name == MANIFEST else m.stem.removeprefix("manifest_")
        manifests.append((str(doc.get("finished", "")), m.name, doc, _origin(label, doc)))
    manifests.sort(key=lambda t: t[0])
    files, origins = {}, {}
    for f in sorted(folder.iterdir()):
        if f.name == RECORD or not f.is_file() or f.suffix not in KEPT_SUFFIXES:
            continue
        label = "bench_results" if f.name.startswith("bench_") else "unknown"
        origin = {"source": label}
        for _, mname, doc, o in manifests:  # oldest first: the newest that lists it wins
            if f.name == mname or f.name in doc.get("outputs", []):
                label, origin = o["source"], o
        origins[label] = origin
        files[f.name] = label
    return {"command": "trunkslam report", "origins": origins, "files": files}

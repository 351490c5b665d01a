"""No input lost, no folder of the user's replaced, a full disk a clear error (issue 29).

- Inputs overwritten: the six commands of the issue, as real processes, each refused before any
  work with an `error:` naming the option and the input, the input byte for byte as it was;
  then `check_outputs`, the one check every command makes, against links, hard links, folders
  holding inputs, outputs inside input folders and the package's own scene and preset files.
- A folder of the user's: a result folder is replaced only when every file in it is listed in
  its manifest.json by the command now writing it; a foreign file is named and kept.
- A full disk: a small full file system (a tmpfs in a private mount namespace, `unshare -rm`,
  where the sandbox allows it) and a file-size limit (RLIMIT_FSIZE: writes past N bytes fail
  with EFBIG, a stand-in that needs no privilege): exit 1, an `error:` naming the path, nothing
  left behind, no hang.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from subprocesses import TRUNKSLAM, error_line, trunkslam
from support import invoke, snapshot
from typer.testing import CliRunner

from experiments.bundled import presets_dir, scenes_dir
from experiments.cli import app
from experiments.errors import DataError
from experiments.io.outputs import MANIFEST, check_output_folder, check_outputs

runner = CliRunner()
SWEEP = 'study = "association"\ntrials = 1\nseed = 1\n[base]\n"sim.n_scans" = 4\n'
SWEEP += "[grid]\ngate_prob = [0.9]\n"


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A 12-scan drive, an earlier `slam` output of it, a sweep output: read-only, copy them."""
    d = tmp_path_factory.mktemp("outputs")
    invoke("simulate-drive", "--scans", "12", "--seed", "3", "--out", d / "drive.npz")
    invoke("slam", d / "drive.npz", "--out", d / "prev")
    (d / "sw.toml").write_text(SWEEP)
    invoke("sweep", d / "sw.toml", "--out", d / "sweep", "--workers", "1")
    return d


def copy(src: Path, dest: Path) -> Path:
    if src.is_dir():
        shutil.copytree(src, dest)
    else:
        shutil.copy2(src, dest)
    return dest


# ---- inputs overwritten: the six commands ---------------------------------------------


@pytest.mark.slow
def test_slam_rerun_onto_its_own_config_is_refused(made, tmp_path):
    cfg = copy(made / "prev" / "config.toml", tmp_path / "my.toml")
    before = cfg.read_bytes()
    drive = made / "drive.npz"
    args = ["slam", drive, "--config", cfg, "--out", tmp_path / "o", "--rerun", cfg]
    proc = trunkslam(args, tmp_path)
    error_line(proc, "--rerun", cfg, "input")
    assert cfg.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my.toml"]  # no folder, no temporary


@pytest.mark.slow
def test_slam_out_the_folder_holding_its_config_is_refused(made, tmp_path):
    prev = copy(made / "prev", tmp_path / "prev")
    old = snapshot(prev)
    args = ["slam", made / "drive.npz", "--config", prev / "config.toml", "--out", prev]
    proc = trunkslam(args, tmp_path)
    error_line(proc, "--out", prev, "config.toml")
    assert snapshot(prev) == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["prev"]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("command", "package_file"),
    [
        (["simulate", "pillar_court", "--pose", "0,0,0"], ("scenes", "pillar_court.json")),
        (["simulate-drive", "tree_park", "--scans", "2"], ("scenes", "tree_park.json")),
        (["simulate-drive", "tree_park", "--scans", "2"], ("presets", "cycab.toml")),
    ],
)
def test_simulate_onto_a_file_of_the_package_is_refused(command, package_file, tmp_path):
    """The scene a command reads, and any scene or preset the package ships, is never an
    output (their bytes are restored should the command overwrite one anyway)."""
    folder, name = package_file
    path = Path(str((scenes_dir() if folder == "scenes" else presets_dir()) / name))
    before = path.read_bytes()
    try:
        proc = trunkslam([*command, "--out", path], tmp_path)
        after = path.read_bytes()
    finally:
        if path.read_bytes() != before:
            path.write_bytes(before)
    assert after == before
    error_line(proc, "--out", name, "package")
    assert not list(path.parent.glob(f".{name}.*"))  # no temporary file beside it


@pytest.mark.slow
def test_sweep_out_the_folder_holding_its_spec_is_refused(made, tmp_path):
    so = copy(made / "sweep", tmp_path / "so")
    copy(made / "sw.toml", so / "sw.toml")
    old = snapshot(so)
    proc = trunkslam(["sweep", so / "sw.toml", "--out", so, "--workers", "1"], tmp_path)
    error_line(proc, "--out", so, "sw.toml")
    assert snapshot(so) == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["so"]


@pytest.mark.slow
@pytest.mark.data
def test_convert_onto_the_data_readme_is_refused(vp_dir, tmp_path):
    """The README the sha256 sums are read from, named directly or through a symlinked folder,
    and any other file of the data folder."""
    from experiments.io.victoria_park import VP_FILES

    data = tmp_path / "victoria_park"
    for rel in VP_FILES.values():
        (data / rel).parent.mkdir(parents=True, exist_ok=True)
        (data / rel).symlink_to(vp_dir / rel)
    readme = copy(vp_dir / "README.md", data / "README.md")
    readme.chmod(0o644)
    before = readme.read_bytes()
    (tmp_path / "alias").symlink_to(data)
    for out in (readme, tmp_path / "alias" / "README.md", data / "notes.npz"):
        proc = trunkslam(["convert", "victoria-park", "--data", data, "--out", out], tmp_path)
        error_line(proc, "--out", out, "input")
        assert readme.read_bytes() == before
    assert sorted(p.name for p in data.iterdir()) == sorted(
        ["README.md", *{rel.split("/")[0] for rel in VP_FILES.values()}]
    )


# ---- the one check --------------------------------------------------------------------------


def test_check_outputs_refuses_inputs_by_any_name(tmp_path):
    """An output that is an input (directly, through a symlinked folder, or a hard link), a
    folder holding an input, an output inside an input folder, two outputs on one path."""
    inp = tmp_path / "data" / "in.npz"
    inp.parent.mkdir()
    inp.write_bytes(b"input")
    (tmp_path / "alias").symlink_to(tmp_path / "data")
    os.link(inp, tmp_path / "hard.npz")
    cases = [
        ({"--out": inp}, {}, "is an input"),
        ({"--out": tmp_path / "alias" / "in.npz"}, {}, "is an input"),
        ({"--out": tmp_path / "hard.npz"}, {}, "is an input"),
        ({}, {"--out": tmp_path / "data"}, "holds the input"),
        ({}, {"--out": tmp_path}, "holds the input"),
        ({}, {"--out": tmp_path / "alias"}, "holds the input"),  # resolved: the data folder
        ({"--out": tmp_path / "x.json", "--rerun": tmp_path / "x.json"}, {}, "is also --out"),
    ]
    for files, folders, words in cases:
        with pytest.raises(DataError, match=words) as info:
            check_outputs("slam", inputs=[inp], files=files, folders=folders)
        option = next(iter(files or folders))
        assert option in str(info.value)
    with pytest.raises(DataError, match="inside the input folder"):
        check_outputs("convert", inputs=[tmp_path / "data"], files={"--out": inp.parent / "n.npz"})
    # a recording inside the --out folder is part of the set: allowed
    check_outputs(
        "slam",
        inputs=[inp],
        files={"--rerun": tmp_path / "o" / "r.rrd"},
        folders={"--out": tmp_path / "o"},
    )
    assert inp.read_bytes() == b"input"


def test_check_outputs_refuses_the_package_files(tmp_path):
    """Any scene or preset the package ships (by its path or a hard link to it), a new file in
    those folders, and a folder holding them."""
    scene = Path(str(scenes_dir() / "tree_park.json"))
    preset = Path(str(presets_dir() / "cycab.toml"))
    hard = tmp_path / "hard.json"
    try:
        os.link(scene, hard)
    except OSError:  # another file system: the path cases still run
        hard = scene
    for path, words in [
        (scene, "package"),
        (preset, "package"),
        (hard, "package"),
        (scene.parent / "new.json", "package"),
    ]:
        with pytest.raises(DataError, match=words):
            check_outputs("simulate", files={"--out": path})
    with pytest.raises(DataError, match="package"):
        check_outputs("reproduce", folders={"--out": scene.parent.parent})


# ---- a folder of the user's is not replaced whole ---------------------------------------------


@pytest.mark.slow
def test_slam_refuses_a_result_folder_holding_a_foreign_file(made, tmp_path):
    """The issue's case: thesis.tex beside a summary.json; named, and the folder kept."""
    prev = copy(made / "prev", tmp_path / "prev")
    (prev / "thesis.tex").write_text("years of work")
    old = snapshot(prev)
    proc = trunkslam(["slam", made / "drive.npz", "--out", prev], tmp_path)
    error_line(proc, "--out", prev, "thesis.tex")
    assert snapshot(prev) == old


@pytest.mark.slow
def test_every_result_folder_lists_its_files_in_its_manifest(made, tmp_path):
    """slam, smooth (adding its files to the run's), export-reference, sweep and reproduce."""
    out = copy(made / "prev", tmp_path / "run")
    invoke("smooth", out)
    invoke("export-reference", made / "drive.npz", "--out", tmp_path / "ref")
    for folder, command in [
        (out, "slam"),
        (tmp_path / "ref", "export-reference"),
        (made / "sweep", "sweep"),
    ]:
        m = json.loads((folder / MANIFEST).read_text())
        assert m["command"] == f"trunkslam {command}"
        assert sorted(m["outputs"]) == sorted(set(snapshot(folder)) - {MANIFEST}), folder
    assert {"smoother.json", "trajectory_smoothed.csv"} <= set(
        json.loads((out / MANIFEST).read_text())["outputs"]
    )
    invoke("slam", made / "drive.npz", "--features", "bailey", "--out", out)  # ours: replaced
    assert "smoother.json" not in snapshot(out)


@pytest.mark.slow
def test_folders_not_wholly_ours_are_refused_and_named(made, tmp_path, noise_calibration_set):
    """A foreign file in a subfolder or hidden, a folder without a manifest (an older output),
    a manifest that is not JSON, and another command's result set: each refused, named."""
    drive = made / "drive.npz"
    cases = {}
    a = copy(made / "prev", tmp_path / "a")
    (a / "plots").mkdir()
    (a / "plots" / "fig.pdf").write_text("mine")
    cases[a] = ("slam", "plots/fig.pdf")
    b = copy(made / "prev", tmp_path / "b")
    (b / ".notes").write_text("mine")
    cases[b] = ("slam", ".notes")
    c = copy(made / "prev", tmp_path / "c")
    (c / MANIFEST).unlink()
    cases[c] = ("slam", "no manifest.json")
    d = copy(made / "prev", tmp_path / "d")
    (d / MANIFEST).write_text("{not json")
    cases[d] = ("slam", MANIFEST)
    e = copy(noise_calibration_set, tmp_path / "e")
    cases[e] = ("slam", "trunkslam reproduce")
    f = copy(made / "sweep", tmp_path / "f")
    (f / "sweep_notes.txt").write_text("mine")
    cases[f] = ("sweep", "sweep_notes.txt")
    g = copy(noise_calibration_set, tmp_path / "g")
    (g / "draft.md").write_text("mine")
    cases[g] = ("reproduce", "draft.md")
    for folder, (command, words) in cases.items():
        old = snapshot(folder)
        with pytest.raises(DataError, match=None) as info:
            check_output_folder(folder, "--out", command)
        assert words in str(info.value) and str(folder) in str(info.value), info.value
        assert snapshot(folder) == old
    res = runner.invoke(app, ["slam", str(drive), "--out", str(a)])
    assert res.exit_code == 1 and "plots/fig.pdf" in res.output, res.output
    res = runner.invoke(app, ["export-reference", str(drive), "--out", str(b)])
    assert res.exit_code == 1 and "trunkslam slam" in res.output, res.output
    res = runner.invoke(app, ["reproduce", "noise-calibration", "--quick", "--out", str(g)])
    assert res.exit_code == 1 and "draft.md" in res.output, res.output
    assert (g / "draft.md").read_text() == "mine"


# ---- a full disk -----------------------------------------------------------------------------


def _unshare_works(tmp: Path) -> bool:
    """A tmpfs can be mounted in a private user and mount namespace (`unshare -rm`)."""
    if shutil.which("unshare") is None or shutil.which("mount") is None:
        return False
    tmp.mkdir(exist_ok=True)
    probe = f"mount -t tmpfs -o size=64k none {tmp} && touch {tmp}/x"
    try:
        r = subprocess.run(
            ["unshare", "-rm", "--fork", "sh", "-c", probe], capture_output=True, timeout=30
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0 and not (tmp / "x").exists()  # the file was on the tmpfs


FILL = """
import os, sys
folder, keep = sys.argv[1], int(sys.argv[2])
st = os.statvfs(folder)
with open(os.path.join(folder, "fill"), "wb") as fh:  # the disk, full but for `keep` bytes
    left = st.f_bavail * st.f_frsize - keep
    try:
        while left > 0:
            n = min(left, 1 << 20)
            fh.write(bytes(n))
            fh.flush()
            left -= n
    except OSError:
        pass
"""


def _warm(tmp_path: Path, args: list) -> None:
    """Run the command once with room to spare, beside tmp_path: numba's compiled kernels are
    cached (a file-size limit would otherwise stop numba writing its cache, which is not what
    these tests are about)."""
    warm = tmp_path.parent / f"{tmp_path.name}-warm"
    (warm / "FULL").mkdir(parents=True, exist_ok=True)
    shutil.copy(tmp_path / "drive.npz", warm / "drive.npz")
    proc = trunkslam([str(a).replace("FULL", str(warm / "FULL")) for a in args], warm)
    assert proc.returncode == 0, proc.stderr
    shutil.rmtree(warm)


def _on_full_fs(tmp_path: Path, mechanism: str, args: list, keep: int = 0, prelude="") -> tuple:
    """Run `trunkslam ARGS` (FULL in them: the full file system's folder) and return
    (completed process, sorted names under FULL afterwards, the filler excepted). prelude:
    Python run before the command (in place of `python -m experiments.cli`)."""
    full = tmp_path / "FULL"
    full.mkdir(exist_ok=True)
    _warm(tmp_path, args)
    args = [str(a).replace("FULL", str(full)) for a in args]
    if mechanism == "fsize":  # every file this process writes stops at 64 KiB (slam: 128 KiB,
        # its recording's layout alone is some 66 KiB and rerun's save of a layout that does
        # not fit waits forever; see test_a_disk_that_fills_during_the_recording)
        limit = (128 if args[0] == "slam" else 64) * 1024

        def cap() -> None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

        proc = trunkslam(args, tmp_path, preexec=cap, timeout=120)
        return proc, sorted(str(p.relative_to(full)) for p in full.rglob("*"))
    size_kb = 256 + keep // 1024
    (tmp_path / "fill.py").write_text(FILL)
    command = " ".join(TRUNKSLAM)
    if prelude:
        run = f"{prelude}\nimport sys\nfrom experiments.cli import app\nsys.argv[0] = 'x'\napp()"
        (tmp_path / "run.py").write_text(run)
        command = f"{sys.executable} {tmp_path / 'run.py'}"
    script = (
        f"mount -t tmpfs -o size={size_kb}k none {full} && "
        f"{sys.executable} {tmp_path / 'fill.py'} {full} {keep} && "
        f"{command} {' '.join(args)} > {tmp_path / 'stdout'} 2> {tmp_path / 'stderr'}; "
        f"echo $? > {tmp_path / 'rc'}; find {full} -mindepth 1 -printf '%P\\n' > {tmp_path / 'ls'}"
    )
    r = subprocess.run(["unshare", "-rm", "--fork", "sh", "-c", script], cwd=tmp_path, timeout=180)
    assert r.returncode == 0
    proc = subprocess.CompletedProcess(
        args,
        int((tmp_path / "rc").read_text()),
        (tmp_path / "stdout").read_text(),
        (tmp_path / "stderr").read_text(),
    )
    left = sorted(n for n in (tmp_path / "ls").read_text().split() if n != "fill")
    return proc, left


@pytest.fixture(scope="module", params=["tmpfs", "fsize"])
def mechanism(request, tmp_path_factory):
    if request.param == "tmpfs" and not _unshare_works(tmp_path_factory.mktemp("probe") / "m"):
        pytest.skip("no tmpfs in a private mount namespace here (unshare -rm); fsize runs")
    return request.param


@pytest.mark.slow
@pytest.mark.parametrize(
    ("case", "args", "named"),
    [
        ("slam, recording", ["slam", "drive.npz", "--out", "o1", "--rerun", "FULL/s.rrd"], "s.rrd"),
        (
            "extract, recording",
            ["extract", "drive.npz", "--out", "f.json", "--rerun", "FULL/f.rrd"],
            "f.rrd",
        ),  # noqa: E501
        (
            "slam, folder",
            ["slam", "drive.npz", "--out", "FULL/o2", "--rerun", "FULL/o2/r.rrd"],
            "o2",
        ),  # noqa: E501
    ],
)
def test_a_full_disk_is_an_error_naming_the_path_and_leaves_nothing(
    made, tmp_path, mechanism, case, args, named
):
    copy(made / "drive.npz", tmp_path / "drive.npz")
    proc, left = _on_full_fs(tmp_path, mechanism, args)
    line = error_line(proc, named)
    assert any(w in line for w in ("No space left", "File too large", "free")), line
    assert left == [], (case, left)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name[0] != ".") == sorted(
        {"drive.npz", "FULL", "fill.py", "stdout", "stderr", "rc", "ls"}
        & {p.name for p in tmp_path.iterdir()}
    ), case  # no o1, no f.json
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


@pytest.mark.slow
@pytest.mark.parametrize("stop", ["free-space check", "write error"])
def test_a_disk_that_fills_during_the_recording(tmp_path, mechanism, stop):
    """Room enough to start, not to finish (128 KiB: the recording's start, its layout, is
    some 66 KiB, and rerun's save waits forever when that does not fit; a 40-scan drive records
    more): the recording is stopped by the free-space check at the next scan, or (that check
    off) by the write error of rerun's file writer; exit 1 naming it, nothing left. The
    free-space minimum to start (16 MiB) is lowered to 0 in the command's process, as a 128 KiB
    test disk needs."""
    if mechanism == "fsize":
        pytest.skip("the file-size limit case is the test above")
    invoke("simulate-drive", "--scans", "40", "--seed", "3", "--out", tmp_path / "drive.npz")
    prelude = "import experiments.render.viz as viz\nviz.Recorder.min_free_bytes = 0"
    if stop == "write error":
        prelude += "\nviz.RECORDING_STOP_FREE_BYTES = 0"
    args = ["slam", "drive.npz", "--out", "o1", "--rerun", "FULL/s.rrd"]
    proc, left = _on_full_fs(tmp_path, mechanism, args, keep=131072, prelude=prelude)
    line = error_line(proc, "s.rrd", "No space left")
    assert left == [] and not (tmp_path / "o1").exists(), (line, left)

"""`trunkslam export-reference`: a sequence's references as TUM files, for evo_ape and friends.

gps.tum          the GPS fixes a run over the sequence is scored against, those inside the scans'
                 time span (`experiments.eval.gps.fixes_in_run`), `t x y 0 0 0 0 1` (no
                 orientation: identity)
gps_clean.tum    the same without the fixes flagged as jumps (flagged among those fixes, as the
                 scorer flags them)
truth.tum        the true rear-axle pose at its samples (simulated runs)
trees.csv        the true trees' centres, `x_m,y_m` (simulated runs): the reference map that
                 `trunkslam slam --reference-map` scores a run's map against (GOSPA, OSPA)

Compare gps.tum with a run's trajectory_gps_antenna.tum, and truth.tum with its trajectory.tum:

    evo_ape tum ref/gps.tum out/trajectory_gps_antenna.tum --sync_method interpolation \\
        --t_max_diff 0.11

How evo pairs poses: it takes the file with fewer poses, matches each of its stamps to the
nearest stamp of the other file within --t_max_diff (default 0.01 s), and with
`--sync_method interpolation` resamples the other file at the matched stamps (positions linear).
Our scorer (`experiments.eval.gps`) compares every fix with the run's pose interpolated at the
fix's time. Where the fixes are fewer than the scans (Victoria Park) evo therefore resamples the
run at each fix's time, the same fixes and the same pairing as ours, provided --t_max_diff lets
every fix match: a fix inside the run's span lies between two scans, so within half the longest
scan interval of one (`evo_t_max_diff`; 0.1075 s in Victoria Park, 0.1 s in the simulated
drives, so 0.11 covers both). The numbers then agree up to the antenna lever arm: evo
interpolates the antenna point linearly between two scans, we interpolate the pose and place the
antenna on it; the two differ by at most |antenna| (1 - cos(dtheta / 2)) for a heading change
dtheta between the scans. evo's default 0.01 s matches only the fixes that happen to fall within
10 ms of a scan (447 of 4465 in Victoria Park) and compares each with the nearest scan's pose.

Where the GPS is denser than the scans (the simulated DGPS: 10 Hz, scans 5 Hz) evo resamples
the GPS instead: each scan is compared with the GPS interpolated at its time (the first and last
fix held beyond the ends), which averages part of the GPS noise away and gives a lower figure
than ours. A simulated run is checked exactly against truth.tum: its samples (the odometry's)
outnumber the scans, so evo interpolates the truth at the scan times as our summary does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.eval.gps import fixes_in_run, flag_jumps, top_speed
from experiments.io.outputs import check_output_folder, check_outputs, lock_folder, write_manifest
from experiments.io.results import trajectory_tum
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import atomic_folder, write_atomic

__all__ = ["ReferenceExport", "evo_t_max_diff", "export_reference"]


@dataclass(frozen=True)
class ReferenceExport:
    """What `export_reference` wrote: files (paths), n_fixes (the fixes in gps.tum, 0 without
    GPS), n_scans (the sequence's), t_max_diff_s (`evo_t_max_diff` of its scans)."""

    files: list[Path]
    n_fixes: int
    n_scans: int
    t_max_diff_s: float


def evo_t_max_diff(scan_t: np.ndarray) -> float:
    """The smallest evo_ape --t_max_diff (s, rounded up to the millisecond) that matches every
    fix inside the scans' span with a scan: half the longest scan interval (see the module doc).
    """
    dt = np.diff(np.asarray(scan_t, dtype=np.float64))
    if dt.size == 0:
        return 0.0
    return math.ceil(round(float(dt.max()) / 2 * 1e3, 6)) / 1e3


def export_reference(input_path: Path | str, out_dir: Path | str) -> ReferenceExport:
    """Write the reference TUM files of the sequence file `input_path` into out_dir, as one set
    (`experiments.io.writers.atomic_folder`, with its manifest.json: out_dir is replaced as a
    whole, and must be absent, empty or an earlier export every file of which its manifest
    lists; it is held, `lock_folder`, while the command runs)."""
    out = Path(out_dir)
    check_outputs("export-reference", inputs=[input_path], folders={"--out": out})
    with lock_folder(out, "--out"):
        check_output_folder(out, "--out", "export-reference")  # again, now that it is held
        return _export(input_path, out)


def _export(input_path: Path | str, out: Path) -> ReferenceExport:
    seq = load_sequence(input_path)
    inside = None if seq.gps_t is None else fixes_in_run(seq.gps_t, seq.scan_t)
    if (inside is None or not inside.any()) and seq.truth_t is None:
        raise DataError(
            f"{input_path}: the sequence has neither GPS inside its scans' time span nor truth "
            "to export"
        )
    names = []
    with atomic_folder(out) as stage:
        if inside is not None and inside.any():
            t, xy = seq.gps_t[inside], seq.gps_xy[inside]
            flat = np.column_stack([xy, np.zeros(t.size)])
            write_atomic(stage / "gps.tum", trajectory_tum(t, flat))
            ok = ~flag_jumps(t, xy, top_speed(seq))
            write_atomic(stage / "gps_clean.tum", trajectory_tum(t[ok], flat[ok]))
            names += ["gps.tum", "gps_clean.tum"]
        if seq.truth_t is not None:
            write_atomic(stage / "truth.tum", trajectory_tum(seq.truth_t, seq.truth_pose))
            names.append("truth.tum")
        if seq.truth_landmarks is not None and len(seq.truth_landmarks):
            xy = np.asarray(seq.truth_landmarks, dtype=np.float64)[:, :2]
            rows = "".join(f"{float(x)!r},{float(y)!r}\n" for x, y in xy)
            write_atomic(stage / "trees.csv", "x_m,y_m\n" + rows)
            names.append("trees.csv")
        write_manifest(stage, "export-reference")  # last: the set is complete
    n_fixes = 0 if inside is None else int(inside.sum())
    files = [out / n for n in names]
    return ReferenceExport(files, n_fixes, seq.n_scans, evo_t_max_diff(seq.scan_t))

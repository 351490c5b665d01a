"""`trunkslam export-reference`: a sequence's references as TUM files, for evo_ape and friends.

gps.tum          every GPS fix at the antenna, `t x y 0 0 0 0 1` (no orientation: identity)
gps_clean.tum    the same without the fixes flagged as jumps (`experiments.eval.gps`)
truth.tum        the true rear-axle pose at its samples (simulated runs)
Compare gps.tum with a run's trajectory_gps_antenna.tum, and truth.tum with its trajectory.tum.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.errors import DataError
from experiments.eval.gps import flag_jumps, top_speed
from experiments.io.results import trajectory_tum
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import atomic_folder, check_output_folder, write_atomic

__all__ = ["export_reference"]


def export_reference(input_path: Path | str, out_dir: Path | str) -> list[Path]:
    """Write the reference TUM files of the sequence file `input_path` into out_dir, as one set
    (`experiments.io.writers.atomic_folder`: out_dir is replaced as a whole, and must be absent,
    empty or an earlier export holding gps.tum or truth.tum)."""
    out = check_output_folder(out_dir, "--out", ("gps.tum", "truth.tum"), inputs=[input_path])
    seq = load_sequence(input_path)
    if seq.gps_t is None and seq.truth_t is None:
        raise DataError(f"{input_path}: the sequence has neither GPS nor truth to export")
    out.parent.mkdir(parents=True, exist_ok=True)
    names = []
    with atomic_folder(out) as stage:
        if seq.gps_t is not None:
            flat = np.column_stack([seq.gps_xy, np.zeros(seq.gps_t.size)])
            write_atomic(stage / "gps.tum", trajectory_tum(seq.gps_t, flat))
            ok = ~flag_jumps(seq.gps_t, seq.gps_xy, top_speed(seq))
            write_atomic(stage / "gps_clean.tum", trajectory_tum(seq.gps_t[ok], flat[ok]))
            names += ["gps.tum", "gps_clean.tum"]
        if seq.truth_t is not None:
            write_atomic(stage / "truth.tum", trajectory_tum(seq.truth_t, seq.truth_pose))
            names.append("truth.tum")
    return [out / n for n in names]

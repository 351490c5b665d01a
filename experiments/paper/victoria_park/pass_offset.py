"""Victoria Park: the trunk's centre offset shared by a pass (`measurement.pass_offset_sd_m`),
derived on scans 1-2000 by leave-one-pass-out prediction (`experiments.eval.pass_offsets`).

The filter runs over scans 1-2000 with the given settings and the white model (the offset
set to 0), and the passes of the landmarks it saw in two passes or more each predict one
another; (s_r, s_a) are the offsets at which each axis's median normalised squared residual is
the chi-square(1) median. The same run's residuals give the drift of the offset within a pass
(`experiments.eval.pass_drift`: the within-pass semivariogram against the view's turn, fitted
by a first-order Gauss-Markov offset of sd s and correlation length L), reported beside it
(`measurement.pass_offset_corr_rad` is not set by it: the preset keeps white errors). No GPS
enters it, and scans 2001-7249 never do. The calibration
(`calibration.py`) runs it last, with the preset it derived; `trunkslam reproduce
victoria-park-pass-offset` runs it alone, with the shipped preset (about a minute).
"""

from __future__ import annotations

import dataclasses
import logging

from experiments.errors import MissingDataError
from experiments.eval.pass_drift import pass_drift
from experiments.eval.pass_offsets import CHI2_1_MEDIAN, PassOffset, pass_offset, passes_of
from experiments.io.victoria_park import load_victoria_park
from experiments.paper import products
from experiments.paper.products import TableSpec
from experiments.paper.registry import experiment
from slam import SlamConfig, run_slam

__all__ = ["FIT_SCANS", "NAME", "TABLE", "derive", "pass_offset_records", "run"]

log = logging.getLogger(__name__)

NAME = "victoria-park-pass-offset"
FIT_SCANS = 2000


def derive(seq, cfg: SlamConfig) -> PassOffset:
    """The pass offset of `cfg`'s run over `seq` with the white model (the offset set to 0),
    its passes by `measurement.pass_gap_s`, with the drift within a pass of the same run."""
    white = cfg.with_(**{"measurement.pass_offset_sd_m": [0.0, 0.0]})
    run = run_slam(seq, white)
    gap = white.measurement.pass_gap_s
    po = pass_offset(passes_of(run, gap_s=gap))
    return dataclasses.replace(po, drift=pass_drift(run, gap_s=gap))


def pass_offset_records(po: PassOffset) -> list[dict]:
    """One row per axis: passes used, the median statistic under the white model and at the
    derived offset, the derived offset; with the drift fitted, its s within a pass, its s from
    the between-pass sill, its correlation length (shared by the axes) and each axis's own."""
    rows = [
        {
            "axis": axis,
            "passes": po.passes,
            "landmarks": po.landmarks,
            "median_white": po.median_white[i],
            "median_derived": po.median_derived[i],
            "sd_m": po.sd_m[i],
        }
        for i, axis in enumerate(("range", "across the line of sight"))
    ]
    d = po.drift
    if d is not None:
        for i, row in enumerate(rows):
            row |= {
                "drift_sd_m": d.sd_m[i],
                "between_sd_m": d.sd_between_m[i],
                "drift_corr_rad": d.corr_rad,
                "axis_corr_rad": d.corr_axis_rad[i],
            }
    return rows


TABLE = TableSpec(
    "victoria_park_pass_offset",
    pass_offset_records,
    index=("axis",),
    values=None,
    labels={
        "passes": "passes used",
        "landmarks": "landmarks",
        "median_white": "median statistic, white model",
        "median_derived": "median statistic, derived s",
        "sd_m": "derived s (m)",
        "drift_sd_m": "drift s within a pass (m)",
        "between_sd_m": "s from the between-pass sill (m)",
        "drift_corr_rad": "drift L, shared (rad)",
        "axis_corr_rad": "drift L, this axis alone (rad)",
    },
    title="Victoria Park: the trunk's offset shared by a pass, leave-one-pass-out (scans 1-2000)",
    notes=lambda po: (
        "Each pass (sightings with no gap over measurement.pass_gap_s) of a landmark seen in "
        "two passes or more is predicted by the information-weighted mean of its other passes; "
        "the statistic is its residual's normalised square along and across its line of sight, "
        "whose median is "
        f"{CHI2_1_MEDIAN:.4f} (chi-square, 1 dof) when the model holds. Derived s: the offset "
        "at which it is (0 when the white model is already there); the median, so that wrong "
        "associations move it little. The drift: the same run's sightings about their "
        "landmark, in their pass's first line of sight; the within-pass semivariogram against "
        "the view's turn d, fitted by r + s^2 (1 - exp(-d / L)), one L for both axes (weighted "
        "least squares, experiments/eval/pass_drift.py); the between-pass sill gives s "
        "independently. The filter's poses, published detections, scans 1-2000; no GPS "
        "(experiments/eval/pass_offsets.py)."
    ),
)


@experiment(
    "victoria-park-pass-offset",
    order=145,
    page="victoria-park-pass-offset.md",
    help="Victoria Park: the trunk's offset shared by a pass, derived on scans 1-2000 (needs "
    "the data; only when named)",
    default=False,
)
def run(ctx) -> None:
    """The registered experiment `victoria-park-pass-offset`: the derivation alone, with the
    shipped preset's settings."""
    from experiments.io.config_file import load_slam_config, preset_path

    try:
        seq = load_victoria_park(n_scans=FIT_SCANS)
    except MissingDataError as exc:
        log.warning("Victoria Park pass offset skipped: %s", exc)
        ctx.config[NAME] = f"skipped: {exc}"
        return
    cfg = load_slam_config(preset_path("victoria_park_ute"))
    po = derive(seq, cfg)
    ctx.config[NAME] = {
        "scans": FIT_SCANS,
        "preset_pass_offset_sd_m": list(cfg.measurement.pass_offset_sd_m),
        "pass_gap_s": cfg.measurement.pass_gap_s,
        "derived_sd_m": list(po.sd_m),
        "rounds": po.rounds,
        "drift_corr_rad": po.drift.corr_rad,
        "drift_sd_m": list(po.drift.sd_m),
        "drift_between_sd_m": list(po.drift.sd_between_m),
    }
    products.tables(ctx, [TABLE], po)

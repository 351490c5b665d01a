"""What the figures show (issue 25): time-series lines stop at gaps (unobserved landmarks, GPS
dropouts, scans without an update) instead of joining across them; every kind of feature has a
colour of its own; the sweep panels have readable titles, y labels with units, the NEES bounds
and a note saying what the error bars are; victoria_park.md is narrow tables, each the pivot
of its CSV; the README's screenshots are in full colour.

The figures are read back as matplotlib objects: `plots.save` is replaced by one that keeps the
figure, so a test looks at the lines as drawn (their data, colours, labels)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from support import assert_tidy_tables

from experiments.paper import slam_figures, sweep_figures
from experiments.paper.victoria_park import figures as vp_figures
from experiments.render import plots

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def drawn(monkeypatch):
    """The figures the plot functions draw, in order (nothing is written)."""
    figs = []
    monkeypatch.setattr(plots, "save", lambda fig, path: figs.append(fig) or path)
    return figs


def _nan_rows(y) -> list[int]:
    return [int(i) for i in np.flatnonzero(np.isnan(np.asarray(y, float)))]


def _lines(ax, label_part: str) -> list:
    return [ln for ln in ax.lines if label_part in (ln.get_label() or "")]


# ---- lines stop at gaps --------------------------------------------------------------------------


def test_break_at_gaps_inserts_a_nan_row_only_where_samples_are_too_far_apart():
    x, y, yy = plots.break_at_gaps(
        [0, 1, 2, 5, 6], [10, 11, 12, 15, 16], np.arange(10).reshape(5, 2), max_step=1
    )
    assert _nan_rows(x) == [3] and _nan_rows(y) == [3]
    assert list(x[[0, 1, 2, 4, 5]]) == [0, 1, 2, 5, 6]
    assert yy.shape == (6, 2) and np.isnan(yy[3]).all() and list(yy[4]) == [6, 7]
    # a step of exactly max_step is no gap; GPS fixes 0.2 s apart with a 3 s dropout
    assert _nan_rows(plots.break_at_gaps([0, 1, 2, 3], [1, 2, 3, 4], max_step=1)[0]) == []
    t = [0.0, 0.2, 0.4, 3.4, 3.6]
    assert _nan_rows(plots.break_at_gaps(t, t, max_step=2.0)[1]) == [3]
    assert plots.gaps_of(t, 2.0) == [(0.4, 3.4)]


def _innovation_series(scans):
    k = len(scans)
    return {
        "label": "paper",
        "scan": np.array(scans),
        "innov": np.full((k, 2), 0.01),
        "sigma": np.full((k, 2), 0.02),
        "style": "-",
    }


def test_innovation_lines_stop_where_the_tree_was_not_observed(drawn):
    # observed at scans 10-12, then not until 20: the line (and its bounds) stop after 12
    slam_figures.plot_innovations([_innovation_series([10, 11, 12, 20, 21])], "t", path=None)
    axes = drawn[0].axes
    for ax in axes[:2]:
        (innov,) = _lines(ax, "paper innovation")
        assert _nan_rows(innov.get_ydata()) == [3]
        assert list(np.asarray(innov.get_xdata())[[2, 4]]) == [12, 20]
        (bound,) = _lines(ax, "paper 3 sigma")
        assert _nan_rows(bound.get_ydata()) == [3]
        assert innov.get_marker() not in (None, "None", "")  # an observation alone still shows
    # observed at every scan: no break
    slam_figures.plot_innovations([_innovation_series([10, 11, 12, 13])], "t", path=None)
    (innov,) = _lines(drawn[1].axes[0], "paper innovation")
    assert _nan_rows(innov.get_ydata()) == []


def test_pose_error_lines_stop_at_missing_scans(drawn):
    scans = np.array([0, 1, 2, 3, 7, 8])
    series = [
        {
            "label": "bailey",
            "scan": scans,
            "err": np.full((6, 3), 0.1),
            "sigma": np.full((6, 3), 0.2),
        }
    ]
    slam_figures.plot_pose_errors(series, "t", path=None)
    for ax in drawn[0].axes[:3]:
        (err,) = _lines(ax, "bailey error")
        assert _nan_rows(err.get_ydata()) == [4]


def _spans(ax) -> list[tuple[float, float]]:
    """The x extents of the shaded vertical bands (axvspan) of an axes."""
    out = []
    for p in ax.patches:
        xy = np.asarray(p.get_xy(), float) if hasattr(p, "get_xy") else None
        if xy is not None and xy.ndim == 2:
            out.append((float(xy[:, 0].min()), float(xy[:, 0].max())))
        elif xy is not None:  # a Rectangle
            out.append((float(p.get_x()), float(p.get_x() + p.get_width())))
    return out


def _yspan(p) -> tuple[float, float]:
    """The y extent of a shaded horizontal band (axhspan: a Rectangle, or a Polygon)."""
    xy = np.asarray(p.get_xy(), float)
    if xy.ndim == 2:
        return float(xy[:, 1].min()), float(xy[:, 1].max())
    return float(p.get_y()), float(p.get_y() + p.get_height())


def test_gps_error_lines_stop_at_dropouts_which_are_shaded(drawn):
    t = np.array([100.0, 100.2, 100.4, 130.0, 130.2, 130.4])
    e = np.array([1.0, 1.1, 1.2, 5.0, 5.1, 5.2])
    jumps = np.zeros(6, bool)
    vp_figures.plot_gps_errors({"EKF": (t, e), "smoother": (t, e / 2)}, jumps, "t", path=None)
    ax = drawn[0].axes[0]
    for name in ("EKF", "smoother"):
        (line,) = _lines(ax, name)
        assert _nan_rows(line.get_ydata()) == [3]
    assert _spans(ax) == [(100.4, 130.0)]
    # fixes 0.2 s apart throughout: one unbroken line, nothing shaded
    vp_figures.plot_gps_errors({"EKF": (t[:3], e[:3])}, jumps[:3], "t", path=None)
    ax = drawn[1].axes[0]
    assert _nan_rows(_lines(ax, "EKF")[0].get_ydata()) == [] and _spans(ax) == []


def test_vp_timeseries_lines_stop_where_no_scan_was_taken(drawn):
    scan_t = np.array([0.0, 0.2, 0.4, 0.6, 9.0, 9.2])  # no scan for 8.4 s
    gps_t = np.array([0.0, 0.2, 9.0])
    vp_figures.plot_vp_timeseries(
        gps_t,
        {"run": np.array([1.0, 2.0, 3.0])},
        np.zeros(3, bool),
        [(0.2, 9.0)],
        scan_t,
        np.linspace(0.5, 1.0, 6),
        {"run": np.arange(6)},
        "t",
        path=None,
        gap_s=2.0,
    )
    nis_ax, map_ax = drawn[0].axes[1], drawn[0].axes[2]
    nis = [ln for ln in nis_ax.lines if len(ln.get_xdata()) > 2]
    assert len(nis) == 1 and _nan_rows(nis[0].get_ydata()) == [4]
    assert _nan_rows(_lines(map_ax, "run")[0].get_ydata()) == [4]
    assert (0.2, 9.0) in _spans(map_ax)


def test_nees_figure_starts_at_scan_1_with_its_band_and_expected_value(drawn):
    avg = np.array([3.0, 2.5, np.nan, 3.5])  # column 0 (scan 0) is left out by consistency()
    slam_figures.plot_consistency({"paper": avg}, (1.1, 5.8), "t", "NEES", None, 3.0, first_scan=1)
    ax = drawn[0].axes[0]
    (line,) = _lines(ax, "paper")
    assert list(np.asarray(line.get_xdata())) == [1, 2, 3, 4]
    assert _nan_rows(line.get_ydata()) == [2]  # a scan without a value stays a gap
    band = [p for p in ax.patches if "95% bounds" in (p.get_label() or "")]
    assert len(band) == 1 and np.allclose(_yspan(band[0]), (1.1, 5.8))
    assert any(ln.get_label().startswith("expected value") for ln in ax.lines)


# ---- colours of the features ---------------------------------------------------------------------


def test_every_kind_of_feature_has_its_own_colour():
    palette = [c for _, c in plots.SEGMENT_COLORS.values()] + list(plots.METHOD_COLORS.values())
    palette += [plots.EDGE_COLOR, plots.SCAN_POINT_COLOR]
    rgb = [to_rgb(c) for c in palette]
    assert len(set(rgb)) == len(rgb), palette
    # the rerun views: segment kinds and circle methods apart too
    from experiments.render.viz import KIND_COLORS, METHOD_COLORS

    colours = [tuple(c) for c in KIND_COLORS.tolist()] + [tuple(c) for c in METHOD_COLORS.values()]
    assert len(set(colours)) == len(colours), colours


def test_feature_figure_draws_segments_and_circles_in_distinct_colours_and_names_them(drawn):
    angles = np.linspace(-np.pi / 2, np.pi / 2, 60)
    points = np.column_stack([10 * np.cos(angles), 10 * np.sin(angles)])
    segments = [((0, 9), 2), ((20, 29), 1), ((40, 49), 0)]  # circle, line, clutter
    circles = [
        ("paper", np.array([[9.0, -7.0, 0.3]]), plots.METHOD_COLORS["paper"]),
        ("bailey", np.array([[9.1, -7.0, 0.3]]), plots.METHOD_COLORS["bailey"]),
    ]
    plots.plot_features(
        points, segments, circles, np.zeros((0, 2)), "t", path=None, zoom=(8, 10, -8, -6)
    )
    fig = drawn[0]
    ax = fig.axes[0]
    seg = {}
    for (a, _), kind in segments:
        (line,) = [
            ln
            for ln in ax.lines
            if len(ln.get_xdata()) == 10 and np.allclose(ln.get_xdata()[0], points[a, 0])
        ]
        seg[kind] = to_rgb(line.get_color())
    circ = {p.get_label(): to_rgb(p.get_edgecolor()) for p in ax.patches if p.get_label()}
    assert set(circ) >= {"circle fit: paper", "circle fit: bailey"}
    drawn_colours = list(seg.values()) + [circ["circle fit: paper"], circ["circle fit: bailey"]]
    assert len(set(drawn_colours)) == 5, drawn_colours
    # the legend names each colour: its entries carry the colours drawn
    (legend,) = fig.legends
    entries = {t.get_text(): h for t, h in zip(legend.get_texts(), legend.legend_handles)}
    assert to_rgb(entries["segment classified circle"].get_color()) == seg[2]
    assert to_rgb(entries["segment classified line"].get_color()) == seg[1]
    assert to_rgb(entries["segment classified clutter"].get_color()) == seg[0]
    assert to_rgb(entries["circle fit: paper"].get_edgecolor()) == circ["circle fit: paper"]


# ---- sweep panels --------------------------------------------------------------------------------


def _slam_rows(metrics, trials=5):
    """sweep_rows-like rows: [point, range_sigma, method, metric, mean, std, n]."""
    rows = []
    for j, x in enumerate((0.01, 0.03)):
        for m in ("paper", "geometric"):
            for name in metrics:
                rows.append([j, x, m, name, 3.0 + j, 0.5, trials])
    return rows


def test_sweep_panels_have_titles_units_nees_bounds_and_say_what_the_bars_are(drawn):
    from experiments.eval.poses import nees_bounds
    from experiments.paper.sweep import METRICS, SweepSpec, _references

    names = ["dx_m", "dtheta_rad", "nees_mean", "nis_per_dof", "landmarks", "false_rate"]
    spec = SweepSpec("slam", 5, 0, [], ["cycab.range_sigma_m"], [], {}, {})
    sweep_figures.plot_sweep_field(
        _slam_rows(names), spec.swept, 0, "t", None, metrics=METRICS, references=_references(spec)
    )
    fig = drawn[0]
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert len(panels) == len(names)
    for ax in panels:
        title, ylabel = ax.get_title(), ax.get_ylabel()
        assert title and title not in names and "_" not in title, title
        assert ylabel and ylabel not in names, ylabel
    assert [ax.get_ylabel() for ax in panels[:2]] == ["|x error| (m)", "|heading error| (rad)"]
    nees_ax = panels[names.index("nees_mean")]
    (band,) = [p for p in nees_ax.patches if "95% NEES bounds" in (p.get_label() or "")]
    assert np.allclose(_yspan(band), nees_bounds(5))
    assert any(ln.get_ydata()[0] == 3.0 for ln in nees_ax.lines if ln.get_linestyle() == "--")
    nis_ax = panels[names.index("nis_per_dof")]
    assert any(ln.get_ydata()[0] == 1.0 for ln in nis_ax.lines if ln.get_linestyle() == "--")
    (legend,) = fig.legends
    assert "standard error" in legend.get_title().get_text()
    assert "n = 5" in legend.get_title().get_text()
    # other studies have no consistency bounds; an unknown metric still gets a readable title
    other = SweepSpec("association", 5, 0, [], ["gate_prob"], [], {}, {})
    assert _references(other) == {}
    sweep_figures.plot_sweep_field(_slam_rows(["odd_metric_m"]), ["gate_prob"], 0, "t", None)
    assert drawn[1].axes[0].get_title() == "odd metric m"


# ---- victoria_park.md ----------------------------------------------------------------------------


class _Ctx:
    def __init__(self, out_dir: Path) -> None:
        self.out_dir = out_dir
        self.outputs: list[Path] = []


def _vp_rows() -> list[dict]:
    from experiments.paper.victoria_park.real_run import COLUMNS

    rows = []
    for i, run in enumerate(("full run, published detections, ihgr", "scans 1-2000, bailey")):
        row = {k: 1.5 + i + j / 7 for j, (k, _) in enumerate(COLUMNS)}
        row.update(run=run, scans=7249 - i, landmarks=300 + i, fixes=4000, jumps=12)
        if i == 0:
            row.pop("published_matched")  # published detections: nothing to match
        rows.append(row)
    return rows


def test_victoria_park_markdown_is_narrow_tables_each_a_pivot_of_the_csv(tmp_path):
    from support import _md_tables

    from experiments.io.writers import read_tidy_csv
    from experiments.paper import products
    from experiments.paper.victoria_park import real_run as vp

    products.tables(_Ctx(tmp_path), [vp.TABLE], _vp_rows())
    assert assert_tidy_tables(tmp_path) == {"victoria_park.csv"}
    tables = _md_tables(tmp_path / "victoria_park.md")
    assert len(tables) == len(vp.PARTS) >= 3
    assert all(len(header) <= 8 for _, _, header, _ in tables), [t[2] for t in tables]
    # the CSV is the one tidy table: every column, one row per run
    rows = read_tidy_csv(tmp_path / "victoria_park.csv")
    assert list(rows[0]) == ["source"] + [k for k, _ in vp.COLUMNS]
    assert len(rows) == 2 and {r["source"] for r in rows} == {"ours"}  # published: own table
    assert math.isnan(rows[0]["published_matched"]) and rows[1]["scans"] == 7248
    md = (tmp_path / "victoria_park.md").read_text()
    assert [line for line in md.splitlines() if line.startswith("## ")] == [
        f"## {h}" for h, _ in vp.PARTS
    ]


def test_published_rows_are_one_table_each_with_its_source(tmp_path):
    """The published figures are printed once, in victoria_park_published (not as n/a rows in
    every part of victoria_park), each with the repository and commit it comes from; the rows
    without a source are gone and the course project is not called Zamora et al.'s."""
    from experiments.io.writers import read_tidy_csv
    from experiments.paper import products
    from experiments.paper.victoria_park import real_run as vp

    products.tables(_Ctx(tmp_path), [vp.TABLE, vp.PUBLISHED_TABLE], _vp_rows())
    assert assert_tidy_tables(tmp_path) == {"victoria_park.csv", "victoria_park_published.csv"}
    assert "| published |" not in (tmp_path / "victoria_park.md").read_text()
    pub = {r["run"]: r for r in read_tidy_csv(tmp_path / "victoria_park_published.csv")}
    assert len(pub) == len(vp.PUBLISHED) == 4
    for r in pub.values():
        assert re.search(r"github\.com/\S+ README\.md at [0-9a-f]{7}", r["reference"]), r[
            "reference"
        ]
    course = next(r for name, r in pub.items() if "course project" in name)
    assert (course["rmse_m"], course["landmarks"]) == (1.394, 182)
    assert "0123gabriel/SLAM-VictoriaPark" in course["reference"]
    assert not any("Zamora" in name or name == "PHD-SLAM" for name in pub)
    assert (
        pub["PHD-SLAM 3.0"]["rmse_rfs_low_m"] == 3.36
        and "16f625a" in pub["PHD-SLAM 3.0"]["reference"]
    )
    assert min(r["rmse_rfs_m"] for r in pub.values() if math.isfinite(r["rmse_rfs_m"])) == 2.46


def test_the_tidy_check_fails_on_a_narrow_table_that_is_not_the_pivot(tmp_path):
    from experiments.paper import products
    from experiments.paper.victoria_park import real_run as vp

    products.tables(_Ctx(tmp_path), [vp.TABLE], _vp_rows())
    md = tmp_path / "victoria_park.md"
    good = md.read_text()
    # a cell changed in the third table
    third = good.index("## Map and consistency")
    cell = good.index("| 300 |", third)
    md.write_text(good[:cell] + "| 301 |" + good[cell + 7 :])
    with pytest.raises(AssertionError, match="victoria_park.csv"):
        assert_tidy_tables(tmp_path)
    # a table left out: its columns are in no pivot
    md.write_text(good[:third])
    with pytest.raises(AssertionError, match="columns in no pivot"):
        assert_tidy_tables(tmp_path)


def test_write_tidy_table_parts_must_split_the_values_exactly(tmp_path):
    from experiments.io.writers import write_tidy_table

    recs = [{"run": "a", "x": 1.0, "y": 2.0, "z": 3.0}]
    with pytest.raises(ValueError, match=r"missing \['z'\]"):
        write_tidy_table(
            tmp_path / "t", recs, ["run"], values=["x", "y", "z"], parts=[("A", ["x", "y"])]
        )
    with pytest.raises(ValueError, match=r"repeated \['x'\]"):
        write_tidy_table(
            tmp_path / "t",
            recs,
            ["run"],
            values=["x", "y", "z"],
            parts=[("A", ["x", "y"]), ("B", ["x", "z"])],
        )
    write_tidy_table(
        tmp_path / "t",
        recs,
        ["run"],
        values=["x", "y", "z"],
        parts=[("A", ["x"]), ("B", ["y", "z"])],
    )
    assert (tmp_path / "t.md").read_text().count("<!-- pivot of t.csv") == 2
    assert assert_tidy_tables(tmp_path) == {"t.csv"}


# ---- rerun series and screenshots ----------------------------------------------------------------


def test_rerun_line_series_are_cleared_at_scans_without_a_value(tmp_path):
    """rerun joins a line series' consecutive values: a clear at the first scan of a gap (NIS
    at scans without an update) stops the line; series drawn as points need none."""
    from rerun.chunk import RrdReader

    from experiments.eval.series import Series
    from experiments.render.viz import MemoryRecorder

    nis = Series("nis", "NIS", np.array([0, 1, 2, 6, 7, 9]), np.ones((6, 3)), ("a", "b", "c"))
    inn = Series("inn", "innov", np.array([0, 5]), np.ones((2, 1)), ("a",), points=True)
    with MemoryRecorder("slam", series=[("nis", "NIS")]) as rec:
        rec.log_series(np.arange(10) * 0.2, [nis, inn])
    path = tmp_path / "s.rrd"
    path.write_bytes(rec.data)
    cleared: dict[str, list[int]] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        d = chunk.to_record_batch().to_pydict()
        if "Clear:is_recursive" in d:
            cleared.setdefault(str(chunk.entity_path).lstrip("/"), []).extend(d["scan"])
    assert cleared == {"series/nis": [3, 8]}


@pytest.mark.parametrize("name", ["rerun_slam.png", "rerun_features.png", "rerun_circles.png"])
def test_readme_screenshots_are_full_colour(name):
    """docs/screenshots.py saves RGB: a 256-colour palette turned the green landmarks grey."""
    from PIL import Image

    with Image.open(ROOT / "docs" / name) as im:
        assert im.mode in ("RGB", "RGBA"), im.mode
        colours = im.convert("RGB").getcolors(maxcolors=1 << 20)
    assert colours is not None and len(colours) > 256


def test_the_closure_map_marks_each_match_by_outcome(drawn):
    """Matches drawn by outcome with their counts in the legend; "too few" is not drawn."""
    xy = np.zeros((5, 2))
    matches = [
        (np.array([1.0, 1.0]), "accepted"),
        (np.array([2.0, 1.0]), "not jointly compatible"),
        (np.array([3.0, 1.0]), "not jointly compatible"),
        (np.array([4.0, 1.0]), "beyond dead reckoning"),
        (np.array([5.0, 1.0]), "too few"),
    ]
    vp_figures.plot_closure_map(xy, xy, xy, matches, "t", path=None)
    ax = drawn[0].axes[0]
    assert _lines(ax, "accepted (1)")[0].get_xdata().tolist() == [1.0]
    assert _lines(ax, "not jointly compatible (2)")[0].get_xdata().tolist() == [2.0, 3.0]
    assert len(_lines(ax, "beyond dead reckoning (1)")) == 1
    assert not _lines(ax, "too few") and not _lines(ax, "no margin")

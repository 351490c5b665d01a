"""Probe behind the notebook's entry on the published RFS protocol's bad clutter draws (issue
39, item 3): what the filter did with the clutter in a draw, against the same run without
clutter, scan by scan.

    TRUNKSLAM_DATA=../shared/datasets PYTHONPATH=. .venv/bin/python docs/rfs_draw_probe.py \
        [--draws 72 90 12 99 21] [--protocol-density | --joint-check [--window T0 T1]]

Each draw is re-run exactly as `trunkslam reproduce victoria-park-rfs` runs it
(`experiments.paper.victoria_park.rfs`: the protocol's input, the draw's seed spawned from the
experiment's seed 0, the published fixed start, the `victoria_park_ute` preset, one BLAS
thread), and its protocol RMSE printed beside the snapshot's (docs/results/
victoria_park_rfs_draws.csv): they must agree to the digit before anything else is read. A
false detection is known by its radius (NaN: the protocol's clutter has none; every detection
of the detector has one); the filter never reads it. The real detections are the same, in the
same order, in every draw and in the run without clutter, so their decisions are compared one
by one (landmark ids differ between runs, a clutter tentative takes an id too: they are mapped
by the real detections both runs paired).

Printed per draw: the clutter's fate (used in an update of a mapped landmark, seen again as a
tentative, confirmed into the map, left new, ambiguous); where the draw's path first departs
from the run without clutter (0.1, 0.3, 1 m) and its protocol error before and after that; each
false detection an update used in the scans up to that departure, with its Mahalanobis distance
d2 (the gate: chi2_2(0.999) = 13.8), the heading it moved the estimate by (the heading's
difference from the run without clutter after the scan less before it), the scan's batch NIS
against chi2(0.999) of its dof, and the probability that the detection is clutter rather than
the landmark under IHGR's own likelihoods (`association.single.CostModel`: P_D N(nu; 0, S) /
(1 - P_D) against lambda_b + lambda_c) with the preset's densities and with the protocol's
clutter intensity added (5 per scan, uniform in range over [0, 50] m and in bearing over +-85
deg: 5 / (50 m x 2.967 rad) = 0.0337 per m rad); the real detections the run without clutter
paired with a landmark that the draw did not, in the 100 scans after; and the largest d2 of the
run without clutter's own pairings in the 30 scans before the departure (how near its gate it
already was). With --protocol-density each draw is run a second time with IHGR's clutter
density the preset's plus the protocol's (`association.params.clutter_density`), and its RMSE
and whether every measurement's decision is the same as the preset's are printed.

With --joint-check (issue 39: `[association] joint_check`, off in the preset) only the run
without clutter and the draws are run, each with the joint test of a scan's pairings on, and
printed beside the snapshot's figure of the same run (the preset, check off): protocol RMSE,
landmarks, the pairings the check dropped (false detections, real ones, scans), the false
detections an update still used, and the scans where the check dropped a real pairing and
kept a false one (the first three with their NIS after the check). With --window T0 T1
(seconds from the first scan) each run's scans in [T0, T1] where the check dropped a pairing or
an update used a false detection are printed too: the scan's NIS and dof after the check, each
pairing dropped (false or real, the landmark's id) and each false detection used (the landmark's
id, its d2).
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.stats import chi2
from threadpoolctl import threadpool_limits

from association.single import CostModel
from experiments.exec import spawn_seeds
from experiments.io.victoria_park import load_victoria_park
from experiments.paper.runner import experiment_seed
from experiments.paper.victoria_park import rfs
from experiments.paper.victoria_park.real_run import run_config
from slam import run_slam, se2
from slam.log import AMBIGUOUS, CONFIRMED, NEW_TENTATIVE, TENTATIVE_HIT

SNAPSHOT = Path(__file__).resolve().parent / "results" / "victoria_park_rfs_draws.csv"
GATE = chi2.ppf(0.999, 2)
# the protocol's clutter: mean 5 per scan, uniform over [0, 50] m x [-85, 85] deg
PROTOCOL_DENSITY = rfs.PROTOCOL.clutter_rate / (
    rfs.PROTOCOL.fov_range_m * 2 * rfs.PROTOCOL.fov_angle_rad
)


def load():
    """(protocol input, the preset's configuration): as `rfs` reads them."""
    full = load_victoria_park(full=True)
    raw = load_victoria_park()
    cfg = run_config("detections", "ihgr")
    return rfs.protocol_input(full, raw, cfg), cfg


def run_draw(inp, cfg, draw: int) -> dict:
    """The run of clutter draw `draw` (0: without clutter) as `rfs.rfs_trial` makes it."""
    seq, clutter = inp.seq, 0
    if draw > 0:
        seed = spawn_seeds(experiment_seed(0, rfs.NAME), rfs.PROTOCOL.draws)[draw - 1]
        seq, clutter = rfs.with_clutter(inp, np.random.default_rng(seed))
    lg = run_slam(seq, cfg, prior=rfs.start_prior(cfg.vehicle.laser_pose))
    laser = np.array([se2.compose(p, lg.antenna_pose)[:2] for p in lg.pose])
    scored = np.flatnonzero(inp.detected[: lg.n_scans])
    errors = rfs.score_at_scans(seq.scan_t[scored], laser[scored], seq.gps_t, seq.gps_xy)
    return {"log": lg, "errors": errors, "scored": scored, "clutter": clutter}


def snapshot_rows() -> list[dict]:
    """The snapshot's rows of the clutter draws."""
    with SNAPSHOT.open() as f:
        return [r for r in csv.DictReader(f) if r["run"] == rfs.ROWS["clutter"]]


def snapshot_rmse() -> dict:
    """draw -> the snapshot's protocol RMSE of that clutter draw."""
    return {int(r["draw"]): float(r["rmse_protocol_m"]) for r in snapshot_rows()}


def snapshot_pooled(far_m: float = 4.0) -> str:
    """The snapshot's pooled RMSE over its draws (each draw's squared RMSE weighted by its
    scans scored), and the same without the draws above `far_m`."""
    rows = snapshot_rows()
    e = np.array([float(r["rmse_protocol_m"]) for r in rows])
    n = np.array([float(r["scans_scored"]) for r in rows])
    keep = e <= far_m
    pooled = math.sqrt(np.sum(n * e**2) / n.sum())
    near = math.sqrt(np.sum(n[keep] * e[keep] ** 2) / n[keep].sum())
    return (
        f"snapshot: {len(rows)} draws pooled {pooled:.3f} m, median draw {np.median(e):.3f} m; "
        f"without the {int((~keep).sum())} draws above {far_m} m ({np.sort(e[~keep]).round(2)}"
        f"): {near:.3f} m"
    )


def id_map(lg, lg0, real: np.ndarray) -> dict:
    """draw's landmark/tentative id -> the run without clutter's: the pairing of the real
    detections both runs tracked, most frequent first."""
    ta, tb = lg.meas_track[real], lg0.meas_track
    both = (ta >= 0) & (tb >= 0)
    out: dict = {}
    for (a, b), _ in Counter(zip(ta[both].tolist(), tb[both].tolist())).most_common():
        out.setdefault(a, b)
    return out


def p_clutter(d2: float, S: np.ndarray, model: CostModel, extra: float = 0.0) -> float:
    """P(the detection is clutter or a new landmark | it lies at d2 in the landmark's gate),
    IHGR's likelihoods: lambda / (lambda + P_D N(nu; 0, S) / (1 - P_D))."""
    lam = model.birth_density + model.clutter_density + extra
    n = math.exp(-0.5 * d2) / (2 * math.pi * math.sqrt(np.linalg.det(S)))
    r = model.p_detect * n / (1 - model.p_detect)
    return lam / (lam + r)


def heading_gap(lg, lg0) -> np.ndarray:
    """(N,) the draw's heading less the run without clutter's, wrapped."""
    return (lg.pose[:, 2] - lg0.pose[:, 2] + math.pi) % (2 * math.pi) - math.pi


def clutter_fate(lg, clut: np.ndarray) -> str:
    st = lg.meas_status
    counts = {
        "updated a landmark": clut & (st >= 0),
        "tentative seen again": clut & (st == TENTATIVE_HIT),
        "confirmed into the map": clut & (st == CONFIRMED),
        "new tentative": clut & (st == NEW_TENTATIVE),
        "ambiguous": clut & (st == AMBIGUOUS),
    }
    return ", ".join(f"{k} {int(v.sum())}" for k, v in counts.items())


def departures(lg, lg0) -> dict:
    """threshold m -> first scan where the draw's rear-axle path is that far from the run
    without clutter's (None: never)."""
    gap = np.hypot(*(lg.pose[:, :2] - lg0.pose[:, :2]).T)
    return {m: (int(np.argmax(gap > m)) if (gap > m).any() else None) for m in (0.1, 0.3, 1.0)}


def clutter_updates(lg, lg0, clut, upto: int, ids: dict) -> list[str]:
    """A line per false detection an update used in scans <= upto."""
    model, dh, lines = CostModel(), heading_gap(lg, lg0), []
    t0 = lg.scan_t[0]
    for i in np.flatnonzero(clut & (lg.meas_status >= 0) & (lg.meas_scan <= upto)):
        k = int(lg.meas_scan[i])
        j = np.flatnonzero((lg.obs_scan == k) & (lg.obs_feature == lg.meas_feature[i]))[0]
        nu, S = lg.obs_innov[j], lg.obs_innov_cov[j]
        d2 = float(nu @ np.linalg.solve(S, nu))
        lid = int(lg.meas_status[i])
        dof = int(lg.scan_nis_dof[k])
        lines.append(
            f"  scan {k} ({lg.scan_t[k] - t0:6.1f} s) lm {lid} (no-clutter id "
            f"{ids.get(lid, '-')}) r {lg.meas_z[i, 0]:4.1f} m d2 {d2:4.1f} heading moved "
            f"{math.degrees(dh[k] - dh[k - 1]):+.3f} deg; scan NIS {lg.scan_nis[k]:.1f}/{dof} "
            f"(bound {chi2.ppf(0.999, dof):.1f}); P(clutter) preset {p_clutter(d2, S, model):.1e}"
            f", + protocol {p_clutter(d2, S, model, PROTOCOL_DENSITY):.1e}"
        )
    return lines


def largest_p_clutter(lg, clut) -> str:
    """The largest P(clutter) (`p_clutter`) of any false detection an update used in the run,
    with the preset's densities and with the protocol's added."""
    model, worst = CostModel(), [0.0, 0.0]
    for i in np.flatnonzero(clut & (lg.meas_status >= 0)):
        k = lg.meas_scan[i]
        j = np.flatnonzero((lg.obs_scan == k) & (lg.obs_feature == lg.meas_feature[i]))[0]
        nu, S = lg.obs_innov[j], lg.obs_innov_cov[j]
        d2 = float(nu @ np.linalg.solve(S, nu))
        worst[0] = max(worst[0], p_clutter(d2, S, model))
        worst[1] = max(worst[1], p_clutter(d2, S, model, PROTOCOL_DENSITY))
    return f"preset {worst[0]:.1e}, + protocol {worst[1]:.1e}"


def lost_pairings(lg, lg0, real, ids, k0: int, k1: int) -> tuple[int, int]:
    """(real detections the run without clutter paired with a landmark in scans k0..k1, of
    them those the draw did not pair with the same landmark)."""
    sa, sb = lg.meas_status[real], lg0.meas_status
    mapped = np.array([ids.get(s, -1) if s >= 0 else s for s in sa.tolist()])
    w = (lg0.meas_scan >= k0) & (lg0.meas_scan <= k1) & (sb >= 0)
    return int(w.sum()), int((w & (mapped != sb)).sum())


def nearest_gate(lg0, k0: int, k1: int) -> float:
    """The largest d2 of the run without clutter's pairings in scans k0..k1."""
    o = np.flatnonzero((lg0.obs_scan >= k0) & (lg0.obs_scan <= k1))
    if not o.size:
        return math.nan
    nu, S = lg0.obs_innov[o], lg0.obs_innov_cov[o]
    return float(np.max(np.einsum("ni,ni->n", nu, np.linalg.solve(S, nu[..., None])[..., 0])))


def rms(e: np.ndarray) -> float:
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2))) if e.size else math.nan


def report(draw: int, got: dict, base: dict, snap: dict) -> None:
    """Print one draw's figures (module doc)."""
    lg, lg0 = got["log"], base["log"]
    clut = ~np.isfinite(lg.meas_radius_m)
    real = np.flatnonzero(~clut)
    if not np.array_equal(lg.meas_z[real], lg0.meas_z):
        raise SystemExit(f"draw {draw}: its real detections differ from the run without clutter")
    ids = id_map(lg, lg0, real)
    e = rfs.pooled_rmse([got["errors"]])
    same = "same to the digit" if e == snap.get(draw) else "DIFFERS"
    print(
        f"\ndraw {draw}: protocol RMSE {e:.4f} m (snapshot {snap.get(draw, math.nan):.4f} m, "
        f"{same}); without clutter {rfs.pooled_rmse([base['errors']]):.4f} m; landmarks "
        f"{lg.landmark_xy.shape[0]} (without clutter {lg0.landmark_xy.shape[0]}); "
        f"false detections {got['clutter']}"
    )
    print(f"  clutter: {clutter_fate(lg, clut)}")
    print(
        f"  largest P(clutter) of a false detection an update used: {largest_p_clutter(lg, clut)}"
    )
    dep = departures(lg, lg0)
    t0 = lg.scan_t[0]
    print(
        "  path departs from the run without clutter: "
        + ", ".join(
            f"{m} m at scan {k} ({lg.scan_t[k] - t0:.1f} s)" if k is not None else f"{m} m never"
            for m, k in dep.items()
        )
    )
    k = dep[0.1]
    if k is None:
        return
    t_sc = lg.scan_t[got["scored"]]
    before = t_sc < lg.scan_t[k]
    print(
        f"  protocol RMSE before that scan {rms(got['errors'][before]):.2f} m (without "
        f"clutter {rms(base['errors'][before]):.2f}), from it on "
        f"{rms(got['errors'][~before]):.2f} m (without clutter "
        f"{rms(base['errors'][~before]):.2f})"
    )
    upto = dep[0.3] if dep[0.3] is not None else k
    lines = clutter_updates(lg, lg0, clut, upto, ids)
    print(f"  false detections used by an update up to scan {upto}: {len(lines)}; the last 4:")
    print("\n".join(lines[-4:]))
    paired, lost = lost_pairings(lg, lg0, real, ids, k, k + 100)
    print(
        f"  scans {k}-{k + 100}: of {paired} real detections the run without clutter paired "
        f"with a landmark, the draw did not pair {lost} with the same one"
    )
    print(
        f"  largest d2 of the run without clutter's pairings in scans {k - 30}-{k}: "
        f"{nearest_gate(lg0, k - 30, k):.1f} (gate {GATE:.1f})"
    )


def with_protocol_density(inp, cfg, draw: int, got: dict) -> None:
    """Run `draw` again with IHGR's clutter density the preset's plus the protocol's; print
    its RMSE, whether its poses and map are the preset run's to the bit, and the measurements
    whose decision differs (landmark and tentative ids mapped between the runs: a tentative
    more or fewer renumbers the later ones)."""
    density = CostModel().clutter_density + PROTOCOL_DENSITY
    alt = run_draw(inp, cfg.with_(**{"association.params": {"clutter_density": density}}), draw)
    a, b = alt["log"], got["log"]
    same = np.array_equal(a.pose, b.pose) and np.array_equal(a.landmark_xy, b.landmark_xy)
    ids = id_map(a, b, np.arange(a.meas_track.size))
    sa = np.array([ids.get(s, -100) if s >= 0 else s for s in a.meas_status.tolist()])
    differ = sa != b.meas_status
    clut = ~np.isfinite(b.meas_radius_m)
    print(
        f"  with IHGR's clutter density {density:.4f} per m rad (preset + protocol): protocol "
        f"RMSE {rfs.pooled_rmse([alt['errors']]):.4f} m, landmarks {a.landmark_xy.shape[0]}; "
        f"poses and map the same as the preset's to the bit: {same}; measurements decided "
        f"otherwise: {int((differ & clut).sum())} false detections, "
        f"{int((differ & ~clut).sum())} real ones"
    )


def snapshot_no_clutter() -> float:
    """The snapshot's protocol RMSE of the run without clutter."""
    with SNAPSHOT.open() as f:
        rows = [r for r in csv.DictReader(f) if r["run"] == rfs.ROWS["no clutter"]]
    return float(rows[0]["rmse_protocol_m"])


def joint_window(lg, clut, dropped, was_clutter, window) -> None:
    """Print the scans in window (t0, t1) s from the first scan where the check dropped a
    pairing or an update used a false detection (module doc)."""
    t = lg.scan_t - lg.scan_t[0]
    used = clut & (lg.meas_status >= 0)
    scans = set(dropped[:, 0].tolist()) | {int(k) for k in lg.meas_scan[used]}
    for k in sorted(k for k in scans if window[0] <= t[k] <= window[1]):
        drops = [
            f"{'false' if f else 'real'} (lm {lid})"
            for (scan, _, lid), f in zip(dropped, was_clutter)
            if scan == k
        ]
        taken = []
        for i in np.flatnonzero(used & (lg.meas_scan == k)):
            j = np.flatnonzero((lg.obs_scan == k) & (lg.obs_feature == lg.meas_feature[i]))[0]
            nu, S = lg.obs_innov[j], lg.obs_innov_cov[j]
            taken.append(f"lm {int(lg.meas_status[i])} d2 {nu @ np.linalg.solve(S, nu):.1f}")
        print(
            f"  scan {k} ({t[k]:.1f} s): NIS {lg.scan_nis[k]:.1f} on {lg.scan_nis_dof[k]} dof "
            f"after the check; dropped: {', '.join(drops) or 'none'}; false detections used: "
            f"{', '.join(taken) or 'none'}"
        )


def with_joint_check(inp, cfg, draws: list[int], snap: dict, window=None) -> None:
    """The run without clutter (draw 0) and `draws` with `association.joint_check` on, each
    beside the snapshot's figure (module doc)."""
    on = cfg.with_(**{"association.joint_check": True})
    snap = {0: snapshot_no_clutter(), **snap}
    for d in [0, *draws]:
        got = run_draw(inp, on, d)
        lg = got["log"]
        clut = ~np.isfinite(lg.meas_radius_m)
        dropped = np.array(lg.joint_dropped, np.int64).reshape(-1, 3)
        first = np.searchsorted(lg.meas_scan, dropped[:, 0])  # each scan's first row
        was_clutter = clut[first + dropped[:, 1]]
        used = clut & (lg.meas_status >= 0)
        kept_false = {int(k) for k in lg.meas_scan[used]} & set(dropped[~was_clutter, 0].tolist())
        print(
            f"draw {d}: joint check on: protocol RMSE {rfs.pooled_rmse([got['errors']]):.4f} m "
            f"(snapshot, check off: {snap.get(d, math.nan):.4f} m), landmarks "
            f"{lg.landmark_xy.shape[0]}; pairings dropped {len(dropped)} (false detections "
            f"{int(was_clutter.sum())}, real {int((~was_clutter).sum())}) in "
            f"{len(set(dropped[:, 0].tolist()))} scans; false detections still used by an "
            f"update {int(used.sum())}; scans where it dropped a real pairing and kept a "
            f"false one {len(kept_false)}",
            flush=True,
        )
        for k in sorted(kept_false)[:3]:  # the first few, scan by scan
            rows = dropped[dropped[:, 0] == k]
            print(
                f"  scan {k} ({lg.scan_t[k] - lg.scan_t[0]:.1f} s): NIS {lg.scan_nis[k]:.1f} on "
                f"{lg.scan_nis_dof[k]} dof after the check; dropped {len(rows)} real pairing(s)"
                f", kept {int((used & (lg.meas_scan == k)).sum())} false one(s)"
            )
        if window is not None:
            joint_window(lg, clut, dropped, was_clutter, window)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--draws", type=int, nargs="+", default=[72, 90, 12, 99, 21])
    ap.add_argument("--protocol-density", action="store_true")
    ap.add_argument("--joint-check", action="store_true")
    ap.add_argument("--window", type=float, nargs=2, metavar=("T0", "T1"))
    args = ap.parse_args()
    if args.window is not None and not args.joint_check:
        ap.error("--window is read with --joint-check only")
    inp, cfg = load()
    if args.joint_check:
        with threadpool_limits(1):
            with_joint_check(inp, cfg, args.draws, snapshot_rmse(), args.window)
        return
    print(
        f"preset closure enabled: {cfg.closure.enabled}; association {cfg.association.method}"
        f", gate_prob {cfg.association.gate_prob}; IHGR densities (preset): {CostModel()}; "
        f"the protocol's clutter density {PROTOCOL_DENSITY:.4f} per m rad"
    )
    snap = snapshot_rmse()
    print(snapshot_pooled())
    with threadpool_limits(1):
        base = run_draw(inp, cfg, 0)
        for d in args.draws:
            got = run_draw(inp, cfg, d)
            report(d, got, base, snap)
            if args.protocol_density:
                with_protocol_density(inp, cfg, d, got)


if __name__ == "__main__":
    main()

"""Probes behind the README's "What is left" of the NEES study: where the tree park's pose NEES
misses its bounds. A script, not part of the package; it runs on calibration seeds (children of
`numpy.random.SeedSequence(ROOT)`, ROOT 1000-1003 by default), never on the reported runs.

    .venv/bin/python docs/consistency_probes.py shuffled --runs 16 --root 1001
    .venv/bin/python docs/consistency_probes.py by-beams
    .venv/bin/python docs/consistency_probes.py occluded --runs 16 --root 1000
    .venv/bin/python docs/consistency_probes.py track-correlation
    .venv/bin/python docs/consistency_probes.py scale --runs 16 --root 1000
    .venv/bin/python docs/consistency_probes.py across-runs

shuffled: for every extractor, the EKF run four ways on the same drives: its own extracted
    circles ("extracted"); the trunks it found, each centre rebuilt as the truth plus its own
    normalised error ("own errors", constant noise model: equals "extracted" for paper and
    bailey up to the false circles); the same errors permuted across the run ("shuffled": same
    values, no tie to the tree, range or time they came from); and Gaussian errors of the noise
    model ("gaussian"). Prints NEES mean, share of scans in bounds (bounds for --runs runs),
    share above.
by-beams: the mean squared normalised range and bearing errors (constant noise model, range bias
    removed) of the circles on trunks, by beams on the trunk and by range, on seeds 1000-1003;
    then the same after a log-linear variance model ln sigma^2 = a + b ln(beams) + c ln(range)
    fitted by maximum likelihood, and that model's coefficients.
scale: `paper` under the constant noise model (its line of range bias for that model), the
    sigmas scaled by 0.8-2: NEES mean, in bounds, and NIS per dof (--runs runs, --root).
occluded: the circles on trunks whose arc ends next to a nearer return (a beam beside the arc
    more than `OCCLUDER_M` in front of the centre: the trunk partly hidden), their normalised
    errors against the others', and the EKF's NEES with them dropped (--runs runs, --root).
track-correlation: the errors of one trunk along a run, normalised by the filter's own R
    (range bias, floors and the fit's covariance as the runs use them): tau = sum over tracks
    of (sum of z)^2 over sum of z^2, 1 when a trunk's errors are independent from scan to scan
    (the factor by which the filter overrates what a track tells it); for whole tracks and for
    10- and 30-scan windows, on seeds 1000-1019 (160 tracks).
across-runs: how much of an extractor's error repeats between runs: the correlation of the
    normalised errors of one trunk at the same scan of two runs (every pair of seeds 1000-1003),
    when every run drives one path and when the path varies (`MONTE_CARLO_PATH`).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
from scipy.optimize import minimize

import experiments.paper.slam as ps
from experiments.eval.detections import dominant_label, false_detections, run_labels
from experiments.eval.poses import consistency, nees, pose_errors
from experiments.exec.trials import spawn_seeds
from experiments.sim.trajectory import MONTE_CARLO_PATH, CycabParams, simulate_cycab_run
from features import extract_features
from slam import run_slam, se2

METHODS = ("paper", "geometric", "bailey")
# the simulated tree park's range biases: the cycab preset's (experiment 2's filter)
RANGE_BIAS = ps.CYCAB_SLAM.measurement.range_bias


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def trunk_errors(seq, feats, laser_w, model, bias) -> np.ndarray:
    """(n, 10) rows (scan, circle, true range, true bearing, normalised range error, normalised
    bearing error, radius, range sigma, bearing sigma, trunk's landmark index) of the circles on
    trunks."""
    s_r, s_rm, s_b, s_t = model
    a0, b0 = bias
    lm = seq.truth_landmarks
    rows = []
    for k, f in enumerate(feats):
        lw = laser_w[k]
        for i, ((a, b), p) in enumerate(zip(f.circle_beams, f.circle_params)):
            one = SimpleNamespace(
                n_circles=1, circle_beams=np.array([[a, b]]), circle_params=np.array([p])
            )
            if false_detections(one, seq.scan_labels[k], lw, lm, 0.5)[1]:
                continue
            j = dominant_label(run_labels(seq.scan_labels[k], a, b), returns_only=True)[0]
            d = lm[j, :2] - lw[:2]
            tr, tb = float(np.hypot(*d)), math.atan2(d[1], d[0]) - lw[2]
            r = math.hypot(p[0], p[1])
            r -= a0 + b0 * r
            sr, sb = s_r + s_rm * tr, math.sqrt(s_b**2 + (s_t / tr) ** 2)
            eb = _wrap(math.atan2(p[1], p[0]) - tb)
            rows.append((k, i, tr, tb, (r - tr) / sr, eb / sb, p[2], sr, sb, j))
    return np.array(rows).reshape(-1, 10)


def seeded_trunk_errors(seed: int, cyc: CycabParams, method: str, model) -> tuple[list, np.ndarray]:
    """One tree-park run on `seed`: its features by `method` and their `trunk_errors` rows
    (`model`'s sigmas, the method's default range bias removed)."""
    seq = simulate_cycab_run(np.random.default_rng(seed), "tree_park", cyc)
    truth = ps.interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
    laser_w = np.array([se2.compose(p, seq.laser_pose) for p in truth])
    params = ps.extractor_params(method, cyc)
    fs = [extract_features(seq.scan(k), method, **params) for k in range(seq.n_scans)]
    bias = RANGE_BIAS.get(method, (0.0, 0.0))
    return fs, trunk_errors(seq, fs, laser_w, model, bias)


def rebuilt(feats, rows, zr, zb) -> list:
    """The features with only the trunk circles, each centre at truth + (zr, zb) sigmas."""
    by_scan: dict[int, list] = {}
    for row, a, b in zip(rows, zr, zb):
        k, _, tr, tb, _, _, rad, sr, sb, _ = row
        r2, b2 = tr + a * sr, tb + b * sb
        by_scan.setdefault(int(k), []).append([r2 * math.cos(b2), r2 * math.sin(b2), rad])
    out = []
    for k, f in enumerate(feats):
        P = np.array(by_scan.get(k, [])).reshape(-1, 3)
        n = P.shape[0]
        out.append(
            replace(
                f,
                circle_params=P,
                circle_cov=np.zeros((n, 3, 3)),
                circle_beams=np.zeros((n, 2), np.int64),
                circle_rms_m=np.zeros(n),
            )
        )
    return out


def _run_arrays(runs: int, n_scans: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pose NEES, scan NIS, NIS dof), each (runs, n_scans): a study's arrays as
    `experiments.eval.poses.consistency` takes them."""
    nan = np.full((runs, n_scans), np.nan)
    return nan, nan.copy(), np.zeros((runs, n_scans), int)


def _record(out: tuple, r: int, lg, truth: np.ndarray) -> None:
    """Run r's pose NEES (the scans after the first) and scan NIS into `out` (`_run_arrays`)."""
    out[0][r, 1:] = nees(pose_errors(lg.pose, truth)[1:], lg.pose_cov[1:])
    out[1][r], out[2][r] = lg.scan_nis, lg.scan_nis_dof


def shuffled(runs: int, root: int) -> None:
    cfg = ps.Exp2Config(n_runs=runs, sensitivity=False, smoother=False)
    seeds = spawn_seeds(np.random.SeedSequence(root), runs)
    N = cfg.cycab.n_scans
    kinds = ("extracted", "own errors", "shuffled", "gaussian")
    res = {(m, v): _run_arrays(runs, N) for m in METHODS for v in kinds}
    for r in range(runs):
        rng = np.random.default_rng(seeds[r])
        prng = np.random.default_rng([root, r])
        seq = simulate_cycab_run(rng, cfg.scene, cfg.cycab)
        truth = ps.interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        laser_w = np.array([se2.compose(p, seq.laser_pose) for p in truth])
        for m in METHODS:
            params = ps.extractor_params(m, cfg.cycab)
            fs = [extract_features(seq.scan(k), m, **params) for k in range(seq.n_scans)]
            model = cfg.slam.measurement.model_for(m, has_cov=False).constant
            rows = trunk_errors(seq, fs, laser_w, model, RANGE_BIAS.get(m, (0.0, 0.0)))
            perm = prng.permutation(rows.shape[0])
            const = cfg.slam.with_(
                **{"measurement.noise": "constant", f"measurement.range_bias.{m}": (0.0, 0.0)}
            )
            n = rows.shape[0]
            variants = {
                "extracted": (fs, cfg.slam),
                "own errors": (rebuilt(fs, rows, rows[:, 4], rows[:, 5]), const),
                "shuffled": (rebuilt(fs, rows, rows[perm, 4], rows[perm, 5]), const),
                "gaussian": (
                    rebuilt(fs, rows, prng.standard_normal(n), prng.standard_normal(n)),
                    const,
                ),
            }
            for v, (F, C) in variants.items():
                lg = run_slam(seq, features=F, association="ihgr", config=C)
                _record(res[(m, v)], r, lg, truth)
    print(f"{runs} runs, seeds SeedSequence({root}).spawn({runs})")
    print("| method | centres | NEES mean | in 95% bounds | above |")
    print("|---|---|---|---|---|")
    for (m, v), a in res.items():
        c = consistency(*a)
        print(f"| {m} | {v} | {c['nees_mean']:.2f} | {c['nees_in']:.2f} | {c['nees_above']:.2f} |")


def _nll(q, e, X) -> float:
    """Negative log-likelihood of zero-mean errors e with ln variance X q."""
    ls = X @ q
    return 0.5 * float(np.sum(e**2 * np.exp(-ls) + ls))


def by_beams(roots=(1000, 1001, 1002, 1003)) -> None:
    cyc = CycabParams(**MONTE_CARLO_PATH)
    cfg = ps.Exp2Config()
    for m in METHODS:
        rows = []
        model = cfg.slam.measurement.model_for(m, has_cov=False).constant
        for s in roots:
            fs, t = seeded_trunk_errors(s, cyc, m, model)
            beams = np.array([fs[int(k)].circle_beams[int(i)] for k, i in t[:, :2]])
            rows.append(np.column_stack([t, beams[:, 1] - beams[:, 0] + 1]))
        t = np.vstack(rows)
        er, eb = t[:, 4] * t[:, 7], t[:, 5] * t[:, 8]  # errors in m and rad
        n, r = t[:, 10], t[:, 2]
        X = np.column_stack([np.ones_like(n), np.log(n), np.log(r)])

        qr = minimize(_nll, [np.log(np.var(er)), 0, 0], args=(er, X), method="BFGS").x
        qb = minimize(_nll, [np.log(np.var(eb)), 0, 0], args=(eb, X), method="BFGS").x
        vr, vb = np.exp(X @ qr), np.exp(X @ qb)
        print(
            f"{m}: {t.shape[0]} circles on trunks; log-linear range coefficients "
            f"{np.round(qr, 2)}, bearing {np.round(qb, 2)}"
        )
        print(
            "| bin | circles | range z^2 (constant) | bearing z^2 (constant) | range (log-linear) "
            "| bearing (log-linear) |"
        )
        print("|---|---|---|---|---|---|")
        bins = [("beams", n, (1, 5, 8, 12, 1000)), ("range m", r, (0, 4, 8, 12, 80))]
        for label, v, edges in bins:
            for lo, hi in zip(edges[:-1], edges[1:]):
                s = (v >= lo) & (v < hi)
                if s.sum() < 10:
                    continue
                print(
                    f"| {label} {lo}-{hi} | {s.sum()} | {np.mean(t[s, 4] ** 2):.2f} | "
                    f"{np.mean(t[s, 5] ** 2):.2f} | {np.mean(er[s] ** 2 / vr[s]):.2f} | "
                    f"{np.mean(eb[s] ** 2 / vb[s]):.2f} |"
                )


# paper's range-bias line under the constant model (noise-calibration before the filter took
# the fit's own covariance for paper circles; the cycab preset's range biases note it)
CONSTANT_MODEL_PAPER_BIAS = (-0.0107, 0.00067)


def scale(runs: int, root: int, factors=(0.8, 1.0, 1.25, 1.5, 2.0)) -> None:
    from slam.measurement import NoiseModel

    cfg = ps.Exp2Config(n_runs=runs, sensitivity=False, smoother=False)
    seeds = spawn_seeds(np.random.SeedSequence(root), runs)
    N = cfg.cycab.n_scans
    measurement = cfg.slam.measurement
    base = measurement.constant_noise["paper"]
    res = {s: _run_arrays(runs, N) for s in factors}
    for r in range(runs):
        seq = simulate_cycab_run(np.random.default_rng(seeds[r]), cfg.scene, cfg.cycab)
        truth = ps.interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        params = ps.extractor_params("paper", cfg.cycab)
        fs = [extract_features(seq.scan(k), "paper", **params) for k in range(seq.n_scans)]
        for s in factors:
            noise = {**measurement.constant_noise, "paper": NoiseModel(*(v * s for v in base))}
            c = replace(
                cfg.slam,
                measurement=replace(
                    measurement,
                    noise="constant",
                    constant_noise=noise,
                    range_bias={**measurement.range_bias, "paper": CONSTANT_MODEL_PAPER_BIAS},
                ),
            )
            lg = run_slam(seq, features=fs, config=c)
            _record(res[s], r, lg, truth)
    print(f"{runs} runs, seeds SeedSequence({root}).spawn({runs}); paper, constant noise")
    print("| sigmas x | NEES mean | in 95% bounds | below | above | NIS per dof |")
    print("|---|---|---|---|---|---|")
    for s, a in res.items():
        c = consistency(*a)
        print(
            f"| {s} | {c['nees_mean']:.2f} | {c['nees_in']:.2f} | {c['nees_below']:.2f} | "
            f"{c['nees_above']:.2f} | {c['nis_per_dof']:.2f} |"
        )


OCCLUDER_M = 0.3


def occluded_edges(f, ranges: np.ndarray) -> np.ndarray:
    """(C,) bool: circle i's first or last beam has a neighbour whose return is more than
    OCCLUDER_M nearer than the centre (something in front hides part of the trunk)."""
    n = ranges.size
    out = np.zeros(f.n_circles, bool)
    for i, ((a, b), p) in enumerate(zip(f.circle_beams, f.circle_params)):
        rc = math.hypot(p[0], p[1])
        for j in (a - 1, b + 1):
            if 0 <= j < n and np.isfinite(ranges[j]) and ranges[j] < rc - OCCLUDER_M:
                out[i] = True
    return out


def occluded(runs: int, root: int) -> None:
    cfg = ps.Exp2Config(n_runs=runs, sensitivity=False, smoother=False)
    seeds = spawn_seeds(np.random.SeedSequence(root), runs)
    N = cfg.cycab.n_scans
    res: dict = {}
    errs: dict = {}
    for r in range(runs):
        seq = simulate_cycab_run(np.random.default_rng(seeds[r]), cfg.scene, cfg.cycab)
        truth = ps.interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
        laser_w = np.array([se2.compose(p, seq.laser_pose) for p in truth])
        for m in METHODS:
            params = ps.extractor_params(m, cfg.cycab)
            fs = [extract_features(seq.scan(k), m, **params) for k in range(seq.n_scans)]
            occ = [occluded_edges(f, np.asarray(seq.scan(k).ranges_m)) for k, f in enumerate(fs)]
            model = cfg.slam.measurement.model_for(m, has_cov=False).constant
            rows = trunk_errors(seq, fs, laser_w, model, RANGE_BIAS.get(m, (0.0, 0.0)))
            hid = np.array([occ[int(k)][int(i)] for k, i in rows[:, :2]], bool)
            errs.setdefault(m, []).append(np.column_stack([rows[:, 4:6], hid]))
            kept = [
                replace(
                    f,
                    circle_params=f.circle_params[~o],
                    circle_cov=f.circle_cov[~o],
                    circle_beams=f.circle_beams[~o],
                    circle_rms_m=f.circle_rms_m[~o],
                )
                for f, o in zip(fs, occ)
            ]
            for v, F in (("all circles", fs), ("partly hidden dropped", kept)):
                lg = run_slam(seq, features=F, association="ihgr", config=cfg.slam)
                _record(res.setdefault((m, v), _run_arrays(runs, N)), r, lg, truth)
    print(f"{runs} runs, seeds SeedSequence({root}).spawn({runs})")
    print(
        "| method | circles on trunks | partly hidden | range z^2 (hidden / rest) | bearing z^2 |"
    )
    print("|---|---|---|---|---|")
    for m, parts in errs.items():
        t = np.vstack(parts)
        h = t[:, 2] > 0

        def ms(v: np.ndarray) -> str:
            return f"{np.mean(v**2):.2f}" if v.size else "-"

        print(
            f"| {m} | {t.shape[0]} | {h.sum()} | {ms(t[h, 0])} / {ms(t[~h, 0])} | "
            f"{ms(t[h, 1])} / {ms(t[~h, 1])} |"
        )
    print("| method | circles | NEES mean | in 95% bounds | above |")
    print("|---|---|---|---|---|")
    for (m, v), a in res.items():
        c = consistency(*a)
        print(f"| {m} | {v} | {c['nees_mean']:.2f} | {c['nees_in']:.2f} | {c['nees_above']:.2f} |")


def _tau(z: np.ndarray, groups: np.ndarray) -> float:
    """sum over groups of (sum of z)^2 over sum of z^2."""
    _, inv = np.unique(groups, axis=0, return_inverse=True)
    sums = np.bincount(inv.ravel(), weights=z)
    return float(np.sum(sums**2) / np.sum(z**2))


def track_correlation(roots=tuple(range(1000, 1020))) -> None:
    cyc = CycabParams(**MONTE_CARLO_PATH)
    slam_cfg = ps.Exp2Config().slam
    print(f"seeds {list(roots)}; tau: 1 when a trunk's errors are independent from scan to scan")
    print("| method | component | circles | E[z^2] | tau, whole track | 10 scans | 30 scans |")
    print("|---|---|---|---|---|---|---|")
    for m in METHODS:
        rows = []
        measure = slam_cfg.measurement.model_for(m)  # the floors and range bias the runs use
        for s in roots:
            seq = simulate_cycab_run(np.random.default_rng(s), "tree_park", cyc)
            truth = ps.interpolate_poses(seq.scan_t, seq.truth_t, seq.truth_pose)
            lm = seq.truth_landmarks
            for k in range(seq.n_scans):
                f = extract_features(seq.scan(k), m, **ps.extractor_params(m, cyc))
                if not f.n_circles:
                    continue
                lw = se2.compose(truth[k], seq.laser_pose)
                z, R = measure.from_features(f)
                for i, (a, b) in enumerate(f.circle_beams):
                    lab = run_labels(seq.scan_labels[k], a, b)
                    j, _, n_ret = dominant_label(lab, returns_only=True)
                    if n_ret == 0 or j >= lm.shape[0]:
                        continue
                    d = lm[j, :2] - lw[:2]
                    er = z[i, 0] - math.hypot(*d)
                    eb = _wrap(z[i, 1] - (math.atan2(d[1], d[0]) - lw[2]))
                    zr, zb = er / math.sqrt(R[i, 0, 0]), eb / math.sqrt(R[i, 1, 1])
                    rows.append((s, j, k, zr, zb))
        t = np.array(rows)
        track = t[:, :2]
        for c, name in ((3, "range"), (4, "bearing")):
            taus = [_tau(t[:, c], track)] + [
                _tau(t[:, c], np.column_stack([track, t[:, 2] // w])) for w in (10, 30)
            ]
            print(
                f"| {m} | {name} | {t.shape[0]} | {np.mean(t[:, c] ** 2):.2f} | "
                + " | ".join(f"{v:.2f}" for v in taus)
                + " |"
            )


def across_runs(roots=(1000, 1001, 1002, 1003)) -> None:
    cfg = ps.Exp2Config()
    print(f"seeds {list(roots)}: correlation of one trunk's normalised errors at the same scan")
    print("| method | paths | pairs | range | bearing |")
    print("|---|---|---|---|---|")
    for m in METHODS:
        model = cfg.slam.measurement.model_for(m, has_cov=False).constant
        for label, cyc in (
            ("one path", CycabParams()),
            ("varied", CycabParams(**MONTE_CARLO_PATH)),
        ):
            err = {}
            for s in roots:
                t = seeded_trunk_errors(s, cyc, m, model)[1]
                err[s] = {(int(k), int(j)): (zr, zb) for k, zr, zb, j in t[:, [0, 4, 5, 9]]}
            pairs = [
                (err[a][key], err[b][key])
                for i, a in enumerate(roots)
                for b in roots[i + 1 :]
                for key in err[a].keys() & err[b].keys()
            ]
            x = np.array(pairs)  # (n, 2 runs, 2 components)
            rho = [float(np.corrcoef(x[:, 0, c], x[:, 1, c])[0, 1]) for c in (0, 1)]
            print(f"| {m} | {label} | {len(pairs)} | {rho[0]:.2f} | {rho[1]:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="probe", required=True)
    p = sub.add_parser("shuffled")
    p.add_argument("--runs", type=int, default=16)
    p.add_argument("--root", type=int, default=1001)
    sub.add_parser("by-beams")
    p = sub.add_parser("occluded")
    p.add_argument("--runs", type=int, default=16)
    p.add_argument("--root", type=int, default=1000)
    sub.add_parser("track-correlation")
    sub.add_parser("across-runs")
    p = sub.add_parser("scale")
    p.add_argument("--runs", type=int, default=16)
    p.add_argument("--root", type=int, default=1000)
    a = ap.parse_args()
    if a.probe == "shuffled":
        shuffled(a.runs, a.root)
    elif a.probe == "scale":
        scale(a.runs, a.root)
    elif a.probe == "occluded":
        occluded(a.runs, a.root)
    elif a.probe == "track-correlation":
        track_correlation()
    elif a.probe == "across-runs":
        across_runs()
    else:
        by_beams()


if __name__ == "__main__":
    main()

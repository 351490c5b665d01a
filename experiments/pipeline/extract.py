"""`trunkslam extract`: features of every scan of a sequence file, as the features JSON."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from experiments.errors import ConfigError
from experiments.io.outputs import check_outputs
from experiments.io.sequence_file import load_sequence
from experiments.io.writers import FEATURES_SCHEMA, dumps_json, features_to_dict, write_atomic
from experiments.render.recording import open_recording
from experiments.render.rerun_sink import recording_file
from features import ExtractorParams, extract_features
from features.bailey import BaileyParams

__all__ = ["run_extract"]


def _base_params(method: str, features) -> dict:
    """The keyword arguments of `extract_features` a configuration's [features] section gives
    `method` ({} without one: the extractor's defaults)."""
    if features is None:
        return {}
    from dataclasses import replace

    return replace(features, method=method, file=None).extractor_kwargs()


def run_extract(
    input_path: Path | str,
    out: Path | str,
    method: str = "paper",
    sigma_r_m: float | None = None,
    line_test: str | None = None,
    rerun_path: Path | str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    *,
    features=None,
    config_file: Path | str | None = None,
) -> dict:
    """Extract features from every scan of `input_path` and write the features JSON to `out`
    (format: docs/formats.md); optionally a rerun recording (rerun_path: a file, or a live
    viewer, `experiments.render.rerun_sink.Viewer`). Returns a summary: scans,
    circles, the output path. Both outputs are written atomically (temporary file, rename);
    an output path that is the input, or not a regular file, is refused before any work.
    features: a `slam.config.FeaturesConfig` whose extractor parameters ([features.extractor],
    or [features.bailey] for bailey) the extraction takes (its method is not used: `method`
    is); sigma_r_m and line_test then replace one parameter each. config_file: the file it was
    read from (an input, never an output)."""
    out = Path(out)
    params = _base_params(method, features)
    if line_test is not None:
        params["line_test"] = line_test
    if sigma_r_m is not None:
        params["sigma_r_m"] = sigma_r_m
    if method == "bailey":
        if line_test is not None or sigma_r_m is not None:
            raise ConfigError("--sigma-r and --line-test do not apply to --method bailey")
        # the detector's constants, then (from a configuration) its noise model
        resolved = asdict(params.get("params") or BaileyParams())
        resolved.update({k: v for k, v in params.items() if k != "params"})
    else:
        resolved = ExtractorParams.from_kwargs(**params).to_dict()
    check_outputs(
        "extract",
        inputs=[input_path, config_file],
        files={"--out": out, "--rerun": recording_file(rerun_path)},
    )
    seq = load_sequence(input_path)
    scans = []
    with open_recording(
        rerun_path, "features", series=[("circles_per_scan", f"circles per scan ({method})")]
    ) as rec:
        for k in range(seq.n_scans):
            scan = seq.scan(k)
            f = extract_features(scan, method, **params)
            scans.append(features_to_dict(f, k))
            rec.set_scan(k, float(seq.scan_t[k]))
            rec.log_scan(scan, path="laser/scan")
            rec.log_features(scan, f, path="laser/features")
            rec.log_scalars("circles_per_scan", {method: f.n_circles})
            if progress is not None and (k % 50 == 0 or k == seq.n_scans - 1):
                progress("extract", k + 1, seq.n_scans)
    doc = {
        "schema": FEATURES_SCHEMA,
        "input": str(input_path),
        "method": method,
        "params": resolved,
        "frame": "laser",
        "scans": scans,
    }
    write_atomic(out, dumps_json(doc))
    return {"scans": seq.n_scans, "circles": sum(len(s["circles"]) for s in scans), "out": out}

"""Fuzzing every file format we read (issue 29): a valid file's parsed structure mutated by
hypothesis (types, shapes, NaN/inf, huge values, missing and extra keys, nesting; tests/hostile.py
`mutated_tree`, `mutated_arrays`), written back, and read by the format's reader, 2,000 examples a
format. Every example either loads into a valid object or raises the project's error (a
`ValueError` subclass: DataError, ConfigError, SlamError, FeaturesError) whose message names the
file; never another exception. A run log that loads is also solved by the smoother, which must
not fail on it either (what `trunkslam smooth` does next).

Each format's test reads one small file per example (a few milliseconds), so that the 2,000
examples take well under a minute on one core; derandomized in CI (`--hypothesis-profile=ci`).
"""

from __future__ import annotations

import functools
import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from hostile import (
    base_config,
    base_features,
    base_run_log,
    base_scene,
    base_sequences,
    base_sweeps,
    mutated_arrays,
    mutated_tree,
    project_errors,
    read,
    write_npz,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

EXAMPLES = 2000
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
_counter = itertools.count()


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def _fresh(folder: Path, suffix: str) -> Path:
    return folder / f"f{next(_counter)}{suffix}"


def assert_loads_or_names_the_file(fmt: str, path: Path):
    """The reader's object, or None after the project's error naming the file; anything else
    fails the test."""
    try:
        return read(fmt, path)
    except project_errors() as exc:
        assert isinstance(exc, ValueError), repr(exc)
        assert str(path) in str(exc), f"{fmt}: the error does not name the file: {exc}"
        return None


# ---- the .npz formats ---------------------------------------------------------------------------


@pytest.mark.slow
@FUZZ
@given(case=st.deferred(lambda: mutated_arrays(base_sequences())))
def test_fuzz_sequence_files(folder, case):
    arrays, raw = case
    path = write_npz(_fresh(folder, ".npz"), arrays, raw)
    seq = assert_loads_or_names_the_file("sequence", path)
    if seq is not None:  # what loads is a valid run: every field checked
        assert seq.n_scans >= 1 and np.all(np.diff(seq.scan_t) > 0)
        assert seq.scan_ranges is None or seq.scan_ranges.shape == (seq.n_scans, seq.n_beams)


@pytest.mark.slow
@FUZZ
@given(case=st.deferred(lambda: mutated_arrays({"run_log": base_run_log()})))
def test_fuzz_run_logs(folder, case):
    from slam.smoother import SmootherOptions, smooth

    arrays, raw = case
    path = write_npz(_fresh(folder, ".npz"), arrays, raw)
    got = assert_loads_or_names_the_file("run_log", path)
    if got is not None:
        problem, _ = got
        try:  # what `trunkslam smooth` does with it: a solve, or the project's error
            smooth(problem, SmootherOptions(marginals=False))
        except project_errors():
            pass


# ---- the JSON and TOML formats ------------------------------------------------------------------


def _write_json(folder: Path, doc) -> Path:
    p = _fresh(folder, ".json")
    p.write_text(json.dumps(doc))
    return p


def _write_toml(folder: Path, doc) -> Path | None:
    import tomli_w

    p = _fresh(folder, ".toml")
    try:
        p.write_text(tomli_w.dumps(doc))
    except (TypeError, ValueError, RecursionError):  # not representable in TOML
        return None
    return p


@pytest.mark.slow
@FUZZ
@given(doc=st.deferred(lambda: mutated_tree(base_features()[0])))
def test_fuzz_features_json(folder, doc):
    feats = assert_loads_or_names_the_file("features", _write_json(folder, doc))
    if feats is not None:
        assert len(feats) == 3 and all(np.isfinite(f.circle_params[:, :2]).all() for f in feats)


@pytest.mark.slow
@FUZZ
@given(doc=st.deferred(lambda: mutated_tree(base_scene())))
def test_fuzz_scene_files(folder, doc):
    scene = assert_loads_or_names_the_file("scene", _write_json(folder, doc))
    if scene is not None:
        assert scene.n_objects >= 0 and np.isfinite(scene.scan_positions).all()


@pytest.mark.slow
@FUZZ
@given(doc=st.deferred(lambda: mutated_tree(base_config(), none=False)))
def test_fuzz_config_files(folder, doc):
    from slam import SlamConfig

    path = _write_toml(folder, doc)
    if path is None:
        return
    cfg = assert_loads_or_names_the_file("config", path)
    if cfg is not None:  # a valid configuration: it round-trips
        assert SlamConfig.from_dict(cfg.to_dict()) == cfg


@functools.cache
def _sweep_mutations(study: str):
    """The study's mutated sweep files, one strategy built once: not again at each example,
    where building it (`st.composite` reads its function's source) and validating it took about
    half of the test's CPU (33.5 -> 17.8 s measured). The same strategy, so the same examples."""
    return mutated_tree(base_sweeps()[study], none=False)


@pytest.mark.slow
@FUZZ
@given(study=st.sampled_from(["association", "slam", "circles"]), data=st.data())
def test_fuzz_sweep_files(folder, study, data):
    doc = data.draw(_sweep_mutations(study))
    path = _write_toml(folder, doc)
    if path is None:
        return
    spec = assert_loads_or_names_the_file("sweep", path)
    if spec is not None:  # every point resolved before any trial
        assert spec.points and len(spec.points) == len(spec.values) and spec.trials >= 1

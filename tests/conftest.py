"""Shared fixtures.

Real data: `vp_dir` is the Victoria Park folder under TRUNKSLAM_DATA (see experiments/data.py).
When the data are absent the tests that need them are skipped, unless TRUNKSLAM_REQUIRE_DATA=1
(CI), in which case they fail with a message saying what is missing.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REQUIRE_DATA_ENV = "TRUNKSLAM_REQUIRE_DATA"


def _missing_data(message: str) -> None:
    if os.environ.get(REQUIRE_DATA_ENV, "").strip() == "1":
        pytest.fail(
            f"{message} ({REQUIRE_DATA_ENV}=1, so missing data is a failure)", pytrace=False
        )
    pytest.skip(f"{message} (set {REQUIRE_DATA_ENV}=1 to make this a failure)")


@pytest.fixture(scope="session")
def vp_dir() -> Path:
    """The Victoria Park folder with every file the readers use; skip or fail if absent."""
    from experiments.errors import DataError
    from experiments.io.paths import victoria_park_dir
    from experiments.io.victoria_park import VP_FILES

    try:
        d = victoria_park_dir()
    except DataError as exc:
        _missing_data(f"Victoria Park data not available: {exc}")
    missing = [f for f in VP_FILES.values() if not (d / f).is_file()]
    if missing:
        _missing_data(f"Victoria Park data incomplete in {d}: missing {missing}")
    return d

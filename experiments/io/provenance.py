"""Where a result came from: the machine, the package versions, the git commit."""

from __future__ import annotations

import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

__all__ = ["git_commit", "machine", "versions"]

REPO = Path(__file__).resolve().parents[2]


def machine() -> str:
    """CPU model, core count, Python version and this process's BLAS threads (once numpy is
    loaded), e.g. for benchmark tables."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    out = f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"
    threads = _blas_threads()
    return out if threads is None else f"{out}, {threads} BLAS thread{'s' * (threads > 1)}"


def _blas_threads() -> int | None:
    if "numpy" not in sys.modules:
        return None
    from threadpoolctl import threadpool_info

    counts = [i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"]
    return max(counts) if counts else None


def git_commit() -> str | None:
    """The repository's HEAD commit, with '+dirty' when the tree has changes; None outside git."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+dirty" if dirty else "")


def versions() -> dict[str, str]:
    """Python, platform and the versions of the packages results depend on."""
    out = {"python": sys.version.split()[0], "platform": platform.platform()}
    for pkg in ("trunkslam", "numpy", "scipy", "numba", "gtsam", "rerun-sdk", "matplotlib"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out

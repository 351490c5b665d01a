"""The tutorial notebook on the site: examples/tutorial.ipynb joins the documentation's files as
`tutorial.ipynb`, which mkdocs-jupyter (mkdocs.yml) executes and renders at every build, so
the numbers on its page are those of that run.

It is taken from examples/ rather than copied or linked into docs/: the kernel runs in the
notebook's folder, and in docs/ the folder `docs/experiments/` (the experiment pages) would be
imported as the `experiments` package.

The rerun viewer is a Jupyter widget that receives the recording from the running kernel; a
static page cannot show it. nbconvert renders a widget as its saved state plus a loader that
fetches the widget manager from unpkg.com, and the rerun widget would then fetch its own code
from rerun's site, to show an empty viewer: the site opens from disk and loads nothing from the
network (tests/test_docs_offline.py). So the page keeps the cell's code and its printed lines,
and the widget's loader, state and view are replaced by a note. A page that does not hold
exactly one of each fails the build (the template changed: look again).

The notebook writes its recording into a new temporary folder; while the site is built, the
kernel's temporary folders go into one the build removes at its end (TMPDIR, which the kernel
inherits), so that builds leave nothing behind.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
NOTEBOOK = "tutorial.ipynb"

_LOADER = re.compile(
    r"<script>\s*\(function\(\) \{\s*function addWidgetsRenderer\(\).*?</script>", re.S
)
_STATE = re.compile(
    r'<script type="application/vnd\.jupyter\.widget-state\+json">.*?</script>', re.S
)
_VIEW = re.compile(r'<script type="application/vnd\.jupyter\.widget-view\+json">.*?</script>', re.S)
VIEWER_NOTE = (
    '<div class="admonition note"><p class="admonition-title">The rerun viewer shows here in'
    " Jupyter</p><p>This page was executed without a browser, so the widget, which receives the"
    " recording from the running kernel, is not on it. The views it opens with are listed in"
    ' the <a href="rerun.html">rerun guide</a>.</p></div>'
)


_build_tmp: dict[str, str | None] = {}  # "dir": the build's TMPDIR, "saved": the one before


def on_pre_build(config):
    _build_tmp["saved"] = os.environ.get("TMPDIR")
    _build_tmp["dir"] = tempfile.mkdtemp(prefix="trunkslam-docs-")
    os.environ["TMPDIR"] = _build_tmp["dir"]


def _end_build() -> None:
    if "dir" not in _build_tmp:
        return
    shutil.rmtree(_build_tmp.pop("dir"), ignore_errors=True)
    saved = _build_tmp.pop("saved")
    if saved is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = saved


def on_post_build(config):
    _end_build()


def on_build_error(error):
    _end_build()


@event_priority(100)  # before mkdocs-jupyter's own on_files, which picks the pages it renders
def on_files(files, config):
    files.append(
        File(
            NOTEBOOK,
            src_dir=str(EXAMPLES),
            dest_dir=config.site_dir,
            use_directory_urls=config.use_directory_urls,
        )
    )
    return files


def without_widgets(html: str) -> str:
    """`html` with the widget loader and state removed and the widget's view replaced by
    `VIEWER_NOTE`; PluginError unless each occurs exactly once."""
    for name, pattern, new in (
        ("widget loader", _LOADER, ""),
        ("widget state", _STATE, ""),
        ("widget view", _VIEW, VIEWER_NOTE),
    ):
        html, n = pattern.subn(new, html)
        if n != 1:
            raise PluginError(f"docs/hooks/notebook.py: {NOTEBOOK}: expected one {name}, found {n}")
    return html


def on_page_content(html, page, config, files):
    if page.file.src_uri == NOTEBOOK:
        return without_widgets(html)
    return html

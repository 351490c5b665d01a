"""The documentation site opens from disk (issue 44): `make docs`, then `build/site/index.html`.

The site is built (mkdocs, as `make docs` does, into a temporary folder; under `make test`, which
builds it with --strict first, that build is read) and every page read
as a browser on file:// would: each link and resource of our own must name a file that is
there (no folder, which a browser shows as a listing from disk), and the only resources from
the network are none (fonts are the system's, the search worker's shim is vendored). Search
runs from disk: the offline plugin writes the index as a script (`search/search_index.js`)
that holds every page. When a headless Chromium is installed, the test also opens the site in
it and checks that a search finds a page (skipped without one).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[tuple[str, str]] = []  # (tag.attribute, value)

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("href", "src") and value:
                self.links.append((f"{tag}.{name}", value))


BUILT_SITE_ENV = "TRUNKSLAM_BUILT_SITE"  # `make test`: the site it built, --strict, just before


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site as `make docs` builds it: the one `make test` built just before the suite (its
    folder in TRUNKSLAM_BUILT_SITE), else built here into a temporary folder."""
    built = os.environ.get(BUILT_SITE_ENV)
    if built:
        path = REPO / built
        assert (path / "index.html").is_file(), f"{BUILT_SITE_ENV}={built}: no site built there"
        return path
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    mkdocs = Path(sys.executable).parent / "mkdocs"
    res = subprocess.run(
        [str(mkdocs), "build", "--strict", "--quiet", "-d", str(out)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    return out


def test_every_link_from_disk_names_a_file(site):
    # 404.html is a web server's page (absolute paths by design); no link leads to it
    pages = sorted(p for p in site.rglob("*.html") if p.name != "404.html")
    assert len(pages) > 20
    broken, remote = [], []
    for page in pages:
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        for what, value in parser.links:
            url = urlsplit(value)
            if url.scheme in ("http", "https"):
                if what != "a.href":  # a resource (script, style, image, font) from the network
                    remote.append((page.relative_to(site), value))
                continue
            if url.scheme or not url.path:  # mailto:, data:, a #anchor on the same page
                continue
            target = (page.parent / unquote(url.path)).resolve()
            if not target.is_file():
                broken.append((str(page.relative_to(site)), value))
    assert not broken, broken[:20]
    assert not remote, remote[:20]


def test_search_runs_from_disk(site):
    script = (site / "search" / "search_index.js").read_text(encoding="utf-8")
    assert script.startswith("var __index = ")
    index = json.loads(script.removeprefix("var __index = "))
    located = {d["location"].split("#")[0] for d in index["docs"]}
    assert {"index.html", "getting-started.html", "experiments/victoria-park.html"} <= located
    shim = re.search(
        r'src="(assets/javascripts/iframe-worker-shim\.js)"', (site / "index.html").read_text()
    )
    assert shim and (site / shim[1]).is_file()


def _chromium() -> str | None:
    for name in ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def test_a_headless_browser_finds_a_page_from_disk(site):
    """Chromium opens index.html from file:// (no flag easing file access: as a user's browser
    would) and runs a search ("Victoria"): the results list names the Victoria Park page."""
    exe = _chromium()
    if exe is None:
        pytest.skip("no headless Chromium installed")
    url = (site / "index.html").as_uri() + "?q=Victoria"
    res = subprocess.run(
        [exe, "--headless", "--no-sandbox", "--virtual-time-budget=15000", "--dump-dom", url],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    assert re.search(r'class="md-search-result__item"', res.stdout), res.stdout[-3000:]
    assert "victoria-park.html" in res.stdout


def test_the_tutorial_page_is_the_notebook_as_run(site):
    """tutorial.html is examples/tutorial.ipynb executed at build time (docs/hooks/notebook.py,
    mkdocs-jupyter): its two figures inline, its scores printed, and in place of the rerun
    widget a note, with no widget loader (it would fetch from unpkg.com) or state left."""
    page = (site / "tutorial.html").read_text(encoding="utf-8")
    assert len(re.findall(r'<img[^>]+src="data:image/png;base64,', page)) == 2
    assert re.search(r"EKF\s+ATE \d\.\d{4} m \| NEES mean", page)
    assert re.search(r"smoothed\s+ATE \d\.\d{4} m \| NEES mean", page)
    assert "The rerun viewer shows here in Jupyter" in page
    for gone in ("addWidgetsRenderer", "unpkg.com", "widget-state+json", "widget-view+json"):
        assert gone not in page, gone

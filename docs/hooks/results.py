"""mkdocs hook: resolve the pages' `{{ table(...) }}`, `{{ cell(...) }}` and `{{ provenance() }}`
macros against the results snapshot `docs/results/` (see `experiments.render.report`).

A macro that the snapshot cannot answer stops the build with the page's name and the reason.
"""

from __future__ import annotations

from pathlib import Path

from experiments.render.report import Snapshot, render_macros

SNAPSHOT = Path(__file__).resolve().parents[1] / "results"


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (mkdocs' signature)
    return render_macros(markdown, Snapshot(SNAPSHOT), where=page.file.src_path)

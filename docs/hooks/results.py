"""mkdocs hook: resolve the pages' `{{ table(...) }}`, `{{ cell(...) }}` and `{{ provenance() }}`
macros against the results snapshot `docs/results/` (see `experiments.render.report`), and put
the index of registered experiments (`experiments.paper.registry.index_table`) where a page says
`<!-- experiments: ... -->`.

A macro that the snapshot cannot answer stops the build with the page's name and the reason.
"""

from __future__ import annotations

import re
from pathlib import Path

from experiments.paper.registry import index_table
from experiments.render.report import Snapshot, render_macros

DOCS = Path(__file__).resolve().parents[1]
SNAPSHOT = DOCS / "results"
EXPERIMENTS = re.compile(r"^<!-- experiments: .*-->$", re.MULTILINE)


def on_page_markdown(markdown, page, config, files):  # noqa: ARG001 (mkdocs' signature)
    markdown = EXPERIMENTS.sub(lambda m: index_table(DOCS / "experiments"), markdown)
    return render_macros(markdown, Snapshot(SNAPSHOT), where=page.file.src_path)

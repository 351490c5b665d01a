"""Strip notebooks to the form they are committed in: no outputs, no execution counts, no
widget state, and only the kernel's name and language in the metadata (the tests check
examples/tutorial.ipynb is in this form, tests/test_notebook.py). `make strip-notebooks` runs
it on every notebook in examples/.

    python examples/strip_notebook.py NOTEBOOK.ipynb [...]

Rewrites each file in place (nbformat's layout) and prints the ones it changed.
"""

import sys
from pathlib import Path

import nbformat

KEPT_CELL_METADATA = ("tags",)  # what a cell's metadata keeps (tags steer the docs' rendering)


def stripped(nb: nbformat.NotebookNode) -> nbformat.NotebookNode:
    """`nb` without outputs, execution counts, widget state or run-specific metadata."""
    for cell in nb.cells:
        cell.metadata = {k: v for k, v in cell.metadata.items() if k in KEPT_CELL_METADATA}
        if cell.cell_type == "code":
            cell.outputs = []
            cell.execution_count = None
    language = nb.metadata.get("language_info", {}).get("name", "python")
    nb.metadata = {
        "kernelspec": nb.metadata.get("kernelspec", {}),
        "language_info": {"name": language},
    }
    return nb


def main(paths: list[str]) -> None:
    for path in map(Path, paths):
        before = path.read_text(encoding="utf-8")
        nb = stripped(nbformat.reads(before, as_version=4))
        after = nbformat.writes(nb) + "\n"
        if after != before:
            path.write_text(after, encoding="utf-8")
            print(f"stripped {path}")


if __name__ == "__main__":
    main(sys.argv[1:])

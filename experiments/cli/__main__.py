"""`python -m experiments.cli`: the `trunkslam` command."""

from experiments.cli import app

if __name__ == "__main__":  # pragma: no cover
    app()

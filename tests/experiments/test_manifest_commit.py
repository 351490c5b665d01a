"""A result set's manifest names the commit its run started from (`git_commit`), and, when the
checkout moved while it ran (a commit, an edit that made it dirty), the commit at its end as
well (`git_commit_at_end`): a run whose tree was edited under it says so."""

from __future__ import annotations

from types import SimpleNamespace

from experiments.paper import reproduce


def _manifest(monkeypatch, tmp_path, commits: list[str | None]) -> dict:
    seen = iter(commits)
    monkeypatch.setattr(reproduce, "git_commit", lambda: next(seen))
    ctx = SimpleNamespace(quick=True, seed=0, config={})
    ledger = reproduce._Ledger(ctx, tmp_path, ())  # reads the commit here, at the start
    executor = SimpleNamespace(describe=lambda: "local")
    return ledger.manifest(["features"], executor)  # and again here, at the end


def test_the_manifest_names_the_commit_the_run_started_from(monkeypatch, tmp_path):
    m = _manifest(monkeypatch, tmp_path, ["a" * 40, "b" * 40 + "+dirty"])
    assert m["git_commit"] == "a" * 40
    assert m["git_commit_at_end"] == "b" * 40 + "+dirty"


def test_an_unmoved_checkout_has_no_end_commit(monkeypatch, tmp_path):
    m = _manifest(monkeypatch, tmp_path, ["a" * 40, "a" * 40])
    assert m["git_commit"] == "a" * 40
    assert "git_commit_at_end" not in m


def test_outside_git_both_are_none_and_nothing_moved(monkeypatch, tmp_path):
    m = _manifest(monkeypatch, tmp_path, [None, None])
    assert m["git_commit"] is None
    assert "git_commit_at_end" not in m

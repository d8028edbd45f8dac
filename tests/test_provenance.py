"""Provenance: the code version a result records."""

from legcal_bench import provenance


def test_dirty_means_uncommitted_code_not_results(monkeypatch):
    calls = []

    def fake_git(*args):
        calls.append(args)
        return "a" * 40 if args[0] == "rev-parse" else ""

    monkeypatch.setattr(provenance, "_git", fake_git)
    provenance.code_version.cache_clear()
    try:
        v = provenance.code_version()
    finally:
        provenance.code_version.cache_clear()
    assert v["commit"] == "a" * 40 and v["dirty"] is False and v["results_version"] == provenance.RESULTS_VERSION
    status = next(c for c in calls if c[0] == "status")
    assert ":(top)legcal_bench" in status and ":(top)calibrators" in status
    assert not any("leaderboard" in a or "reports" in a for a in status)


def test_describe_names_the_commit_and_uncommitted_code():
    v = {"package": "0.1.0", "commit": "0123456789abcdef", "dirty": True, "results_version": 2}
    assert provenance.describe(v) == "legcal-bench 0.1.0, commit 0123456 (uncommitted changes), results version 2"
    assert provenance.stable_hash({"a": 1, "b": 2}) == provenance.stable_hash({"b": 2, "a": 1})

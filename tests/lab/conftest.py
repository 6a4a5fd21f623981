"""Shared fixtures of the lab suites."""

import pytest


@pytest.fixture(autouse=True)
def crop_cache_in_tmp(tmp_path_factory, monkeypatch):
    """The benchmark's crop cache in a temporary folder: the tests leave nothing in out/."""
    from lab.bench import harness

    monkeypatch.setattr(harness, "CROP_CACHE", tmp_path_factory.mktemp("bench_cache"))

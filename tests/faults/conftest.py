"""The fault and load tests share one undisturbed tiny run (the reference, built once per session)."""

from pathlib import Path

import pytest

from .faultkit import run_json


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> tuple[Path, dict]:
    """(store, --json summary) of one undisturbed tiny run."""
    store = tmp_path_factory.mktemp("faults") / "ref"
    return store, run_json(store)

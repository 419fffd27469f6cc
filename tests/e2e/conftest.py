"""The tiny-profile runs the e2e tests share: two stores built once per session (the pipeline takes
a minute or more on a shared 2-core machine), and the `holoflow run` helper that built them."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PROMPT = "a small wooden cabin"


def holoflow_run(store: Path, *extra: str) -> dict:
    """`holoflow run PROMPT --profile tiny --json` into ``store``; its JSON summary."""
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "run",
        PROMPT,
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--profile",
        "tiny",
        "--store",
        str(store),
        "--json",
        *extra,
    ]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


@pytest.fixture(scope="session")
def two_runs(tmp_path_factory):
    """(store a, run summary in a, run summary in b): the same tiny run in two separate stores."""
    base = tmp_path_factory.mktemp("e2e")
    return base / "a", holoflow_run(base / "a"), holoflow_run(base / "b")


@pytest.fixture
def tiny_run():
    return holoflow_run

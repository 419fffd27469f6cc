"""Shared fixtures: numeric tests run on every available device and in float32 and float64; the toy
project (tests/flow/fixtures: a pipeline of small programs) copied into a temp folder."""

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from holoflow.commands import main

TOY = Path(__file__).parent / "flow" / "fixtures"

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
# An empty Hugging Face cache: a developer's own downloads (a depth network that `auto` would pick) never
# change what the tests run; tests that need a cache build one in tmp_path and point HF_HOME at it.
_EMPTY_HF = tempfile.mkdtemp(prefix="holoflow-tests-hf-")
os.environ["HF_HOME"] = _EMPTY_HF
os.environ["HF_HUB_CACHE"] = os.path.join(_EMPTY_HF, "hub")


def _devices():
    import torch

    return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.fixture(params=_devices())
def device(request):
    import torch

    return torch.device(request.param)


@pytest.fixture(params=["float32", "float64"])
def dtype(request):
    import torch

    return getattr(torch, request.param)


class Project:
    """A copy of the toy pipeline with helpers to call `holoflow` in-process or as a process."""

    def __init__(self, root: Path):
        self.root = root
        self.store = root / "artifacts"

    def cli(self, *args, capsys=None):
        """holoflow in-process; returns (exit code, stdout, stderr) when capsys is given."""
        rc = main([*args[:1], "--pipeline", str(self.root / "pipeline.yaml"), *args[1:]])
        if capsys is None:
            return rc
        out, err = capsys.readouterr()
        return rc, out, err

    def run_json(self, *args, capsys):
        rc, out, err = self.cli("run", *args, "--json", capsys=capsys)
        assert rc == 0, err
        return json.loads(out)

    def proc(self, *args, **kw):
        """holoflow as its own process (Popen), for kills and concurrency."""
        cmd = [sys.executable, "-m", "holoflow", args[0], "--pipeline", str(self.root / "pipeline.yaml"), *args[1:]]
        return subprocess.Popen(cmd, cwd=self.root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)

    def store_record(self, summary, stage):
        """The key record of ``stage`` in a run summary."""
        return json.loads((self.store / "keys" / f"{summary['stages'][stage]['key']}.json").read_text())

    def how(self, summary):
        return {n: s["how"] for n, s in summary["stages"].items()}


@pytest.fixture
def project(tmp_path, monkeypatch):
    root = tmp_path / "proj"
    shutil.copytree(TOY, root)
    monkeypatch.delenv("HOLOFLOW_STORE", raising=False)
    monkeypatch.chdir(root)
    return Project(root)

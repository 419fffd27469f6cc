"""Load on one store: four `holoflow run` processes with different prompts at once (tiny profile) and
two `holoflow view` servers beside them (127.0.0.1, a bounded number of requests each). All finish,
the store verifies, and the records say each step was computed once: no key ran twice, every record
names the one run that made it, and a batch of the four prompts afterwards is served from the store.
"""

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from .faultkit import ROOT, popen, run_json, verify_clean

PROMPTS = ["a quiet library", "a sunny kitchen", "an old barn", "a snowy cabin"]
REQUESTS = 10  # per viewer while the runs go
pytestmark = pytest.mark.timeout(900)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _viewer(store: Path, port: int) -> subprocess.Popen:
    pytest.importorskip("viser")
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "view",
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--store",
        str(store),
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
    ]
    return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_listening(proc: subprocess.Popen, port: int, timeout: float = 180.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.5)
    raise AssertionError(f"holoflow view never listened on {port}")


def test_four_runs_and_two_viewers_on_one_store(reference, tmp_path):
    store = tmp_path / "store"
    shutil.copytree(reference[0], store, symlinks=True)  # a latest run for the viewers to show
    ports = [_free_port(), _free_port()]
    viewers = [_viewer(store, p) for p in ports]
    runs = []
    try:
        for v, p in zip(viewers, ports):
            _wait_listening(v, p)
        runs = [popen(store, "--json", prompt=p) for p in PROMPTS]
        answered = [0, 0]
        for i in range(REQUESTS):  # bounded: REQUESTS GETs per viewer, 10 s each at most
            for k, p in enumerate(ports):
                with urllib.request.urlopen(f"http://127.0.0.1:{p}/", timeout=10) as r:
                    answered[k] += r.status == 200
            time.sleep(1.0)
        results = [r.communicate(timeout=800) for r in runs]
        assert [r.returncode for r in runs] == [0] * 4, [e[-2000:] for _, e in results]
        assert answered == [REQUESTS, REQUESTS]
        assert all(v.poll() is None for v in viewers)  # the viewers lived through it
    finally:
        for proc in [*runs, *viewers]:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for v in viewers:
            v.communicate(timeout=60)
    assert [v.returncode for v in viewers] == [0, 0]
    verify_clean(store)

    summaries = [json.loads(out) for out, _ in results]
    ran = [(s["stages"][n]["key"], s["run"]) for s in summaries for n in s["stages"] if s["stages"][n]["how"] == "ran"]
    keys = [k for k, _ in ran]
    assert len(keys) == len(set(keys))  # no step computed twice
    assert len(keys) == 4 * 13  # every step of every prompt computed (all differ)
    for key, run in ran:  # the record names the run that computed it
        assert json.loads((store / "keys" / f"{key}.json").read_text())["provenance"]["run"] == run
    assert len(list((store / "keys").glob("*.json"))) == 13 + len(keys)

    prompts = tmp_path / "prompts.txt"
    prompts.write_text("\n".join(PROMPTS) + "\n")
    batch = run_json(store, "--prompts", str(prompts), prompt=None)
    assert {s["how"] for sc in batch["scenes"] for s in sc["stages"].values()} == {"cached"}

"""The Ray executor joining a cluster started apart (`ray start --head` on loopback, with token
authentication on, stopped by its own pid): the token from the environment or Ray's token file, never
written into the store, a record, a log or the output; no token: one line; a cluster that is gone
(`--address auto` with a stale address file, or a dead HOST:PORT): one line within --connect-timeout.
"""

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

ROOT = Path(__file__).resolve().parents[3]
TOY = ROOT / "tests" / "flow" / "fixtures"
pytestmark = pytest.mark.timeout(300)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _clean_env(**extra) -> dict:
    """This process's environment less any Ray address or token settings, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("RAY_AUTH", "RAY_ADDRESS", "RAY_TMPDIR"))}
    return {**env, **extra}


def _descendants(pid: int) -> list[int]:
    kids: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            kids.setdefault(int(stat.read_text().rsplit(")", 1)[1].split()[1]), []).append(int(stat.parent.name))
        except (OSError, IndexError, ValueError):
            pass
    out, todo = [], [pid]
    while todo:
        for c in kids.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


@pytest.mark.parametrize("how", ["auto", "host:port"])
def test_gone_cluster_fails_within_the_timeout(tmp_path, how):
    """No cluster behind the address (a stale Ray address file for auto): one line after about
    --connect-timeout seconds, not Ray's ten minutes of reconnects. (Before the head fixture starts:
    Ray's ``auto`` prefers any GCS running on this node to the address file.)"""
    if how == "auto":
        from ray._private.services import find_gcs_addresses

        if find_gcs_addresses():
            pytest.skip("a Ray cluster runs on this node: `--address auto` would join it, as Ray does")
    port = _free_port()  # nothing listens there
    raytmp = tmp_path / "raytmp"
    (raytmp / "ray").mkdir(parents=True)
    (raytmp / "ray" / "ray_current_cluster").write_text(f"127.0.0.1:{port}")
    address = "auto" if how == "auto" else f"127.0.0.1:{port}"
    (tmp_path / "home").mkdir()
    done, seconds = _run(
        tmp_path,
        "--executor",
        "ray",
        "--address",
        address,
        "--connect-timeout",
        "3",
        env=_clean_env(HOME=str(tmp_path / "home"), RAY_TMPDIR=str(raytmp)),
        timeout=120,
    )
    assert done.returncode == 2, done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    line = [ln for ln in done.stderr.splitlines() if ln.startswith("holoflow: error:")]
    assert len(line) == 1 and "no Ray cluster answers at" in line[0] and f":{port}" in line[0], done.stderr
    assert "--connect-timeout" in line[0]
    assert 3 <= seconds < 60


@pytest.fixture(scope="module")
def head(tmp_path_factory):
    """(address, token) of a one-node Ray head on 127.0.0.1 with token authentication, started by
    `ray start --head --block` in its own session and stopped by that process's pid."""
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.exists():
        pytest.skip(f"no `ray` command beside {sys.executable}")
    token = secrets.token_hex(16)
    temp = tempfile.mkdtemp(prefix="hf-ray-", dir="/tmp")  # short: Ray's socket paths have a limit
    home = tmp_path_factory.mktemp("head-home")
    port = _free_port()
    log = open(Path(temp) / "head.log", "w")
    proc = subprocess.Popen(
        [
            str(ray_cli),
            "start",
            "--head",
            "--block",
            "--node-ip-address",
            "127.0.0.1",
            "--port",
            str(port),
            "--temp-dir",
            temp,
            "--num-cpus",
            "2",
            "--include-dashboard",
            "false",
            "--disable-usage-stats",
        ],
        env=_clean_env(HOME=str(home), RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token),
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    deadline = time.monotonic() + 120
    try:
        while True:
            if proc.poll() is not None:
                pytest.skip(f"`ray start --head` could not start here: {(Path(temp) / 'head.log').read_text()[-500:]}")
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    pytest.skip("`ray start --head` did not open its port within 120 s")
                time.sleep(0.5)
        time.sleep(2.0)  # the raylet registers after the GCS listens
        yield f"127.0.0.1:{port}", token
    finally:
        pids = _descendants(proc.pid)
        proc.send_signal(signal.SIGTERM)  # `ray start --block` stops its own processes
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        for pid in pids:  # anything of it still alive: only ours, by pid
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        log.close()
        shutil.rmtree(temp, ignore_errors=True)


def _run(tmp_path, *args, env, timeout=240):
    """`holoflow run` of the toy pipeline (a copy) with ``args``; (completed process, seconds)."""
    proj = tmp_path / "proj"
    if not proj.exists():
        shutil.copytree(TOY, proj)
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "run",
        "a prompt",
        "--pipeline",
        str(proj / "pipeline.yaml"),
        "--store",
        str(tmp_path / "store"),
        *args,
    ]
    t0 = time.monotonic()
    done = subprocess.run(cmd, cwd=proj, capture_output=True, text=True, timeout=timeout, env=env)
    return done, time.monotonic() - t0


def _files_hold(root: Path, secret: str) -> list[Path]:
    """Files under ``root`` (links not followed) whose bytes contain ``secret``."""
    return [p for p in root.rglob("*") if p.is_file() and not p.is_symlink() and secret.encode() in p.read_bytes()]


@pytest.mark.parametrize("where", ["env", "file"])
def test_token_reaches_the_cluster_and_nowhere_else(head, tmp_path, where):
    address, token = head
    home = tmp_path / "home"
    (home / ".ray").mkdir(parents=True)
    extra = {"HOME": str(home)}
    if where == "env":
        extra["RAY_AUTH_TOKEN"] = token
    else:
        (home / ".ray" / "auth_token").write_text(token + "\n")
    done, _ = _run(tmp_path, "--executor", "ray", "--address", address, "--json", env=_clean_env(**extra))
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout[done.stdout.index("{\n") :])
    assert {s["how"] for s in summary["stages"].values()} == {"ran"}
    store = tmp_path / "store"
    recs = [json.loads(p.read_text()) for p in (store / "keys").glob("*.json")]
    assert len(recs) == 3 and {r["provenance"]["executor"] for r in recs} == {"ray"}
    assert _files_hold(store, token) == []  # store, records, step logs, run.json
    assert token not in done.stdout and token not in done.stderr


def test_no_token_is_one_line(head, tmp_path):
    address, _ = head
    (tmp_path / "home").mkdir()
    done, seconds = _run(
        tmp_path, "--executor", "ray", "--address", address, env=_clean_env(HOME=str(tmp_path / "home"))
    )
    assert done.returncode == 2, done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    line = [ln for ln in done.stderr.splitlines() if ln.startswith("holoflow: error:")]
    assert len(line) == 1 and "cannot join the Ray cluster" in line[0] and "RAY_AUTH_TOKEN" in line[0], done.stderr
    assert done.stderr.strip() == line[0]  # Ray's once-a-second warnings are held back
    assert seconds < 120

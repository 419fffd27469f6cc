"""SIGKILL of a step or of the runner, concurrent runs, corrupted objects: the store stays consistent."""

import hashlib
import json
import os
import random
import signal
import time
from pathlib import Path

import pytest

LAUNCH = pytest.mark.parametrize("launch", [[], ["--cold"]], ids=["warm", "cold"])


def _consistent(store):
    """Every object matches its name; every key record's outputs exist."""
    for sub in (store / "objects").iterdir():
        for obj in sub.iterdir():
            assert hashlib.sha256(obj.read_bytes()).hexdigest() == obj.name, obj
    for rec_path in (store / "keys").glob("*.json"):
        rec = json.loads(rec_path.read_text())
        for e in rec["outputs"].values():
            assert (store / "objects" / e["digest"][:2] / e["digest"]).is_file()


def _children(pid):
    """(pid, argv, comm) of the processes whose parent is ``pid`` (from /proc; Linux)."""
    out = []
    for stat_file in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat_file.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                argv = (stat_file.parent / "cmdline").read_bytes().split(b"\0")
                comm = (stat_file.parent / "comm").read_text().strip()
                out.append((int(stat_file.parent.name), [a.decode() for a in argv if a], comm))
        except (OSError, IndexError, ValueError):
            pass
    return out


def _descendants(pid):
    """_children of ``pid``, of its children, and so on."""
    out, todo = [], [pid]
    while todo:
        found = _children(todo.pop())
        out += found
        todo += [p for p, _, _ in found]
    return out


def _alive(pid):
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _wait_for_step(project, proc, stage, timeout=20.0):
    """Wait until `stage`'s process runs under the runner (exec'd, or forked from a warm template and
    named after its program); returns its pid."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid, argv, comm in _descendants(proc.pid):
            if any(a.endswith(f"{stage}.py") for a in argv) or comm == f"{stage}.py"[:15]:
                return pid
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError(f"{stage} never started")


def _wait_dead(pid, timeout=10.0):
    deadline = time.monotonic() + timeout
    while _alive(pid):
        assert time.monotonic() < deadline, f"process {pid} still alive"
        time.sleep(0.02)


def _verify_ok(project, capsys):
    rc, out, _ = project.cli("verify", capsys=capsys)
    assert rc == 0 and "all match their hashes" in out


@LAUNCH
def test_killed_step_is_redone_alone(project, capsys, launch):
    project.run_json("p", capsys=capsys)
    proc = project.proc("run", "--set", "upper.mode=title", "--set", "upper.sleep=30", *launch)
    os.kill(_wait_for_step(project, proc, "upper"), signal.SIGKILL)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1 and "stage 'upper' failed (killed by signal 9)" in err
    _consistent(project.store)
    _verify_ok(project, capsys)
    s = project.run_json("--set", "upper.mode=title", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "ran"}


@LAUNCH
def test_killed_runner_mid_step(project, capsys, launch):
    proc = project.proc("run", "p", "--set", "upper.sleep=30", *launch)
    _wait_for_step(project, proc, "upper")
    others = [pid for pid, _, _ in _descendants(proc.pid)]
    assert len(others) == (1 if launch else 2)  # the step (and its warm template)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    for pid in others:
        _wait_dead(pid)  # the step dies with its runner (no orphan)
    _consistent(project.store)
    _verify_ok(project, capsys)
    s = project.run_json(capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "ran"}
    assert list((project.store / "tmp").iterdir()) == []


def test_killed_template_mid_step(project, capsys):
    project.run_json("p", capsys=capsys)
    proc = project.proc("run", "--set", "upper.mode=title", "--set", "upper.sleep=30")
    step = _wait_for_step(project, proc, "upper")
    template = [pid for pid, argv, _ in _children(proc.pid) if "holoflow.flow.executors.template" in argv]
    assert len(template) == 1 and step in [pid for pid, _, _ in _children(template[0])]
    os.kill(template[0], signal.SIGKILL)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 1 and "stage 'upper' failed (killed by signal 9 (its warm template died))" in err
    _wait_dead(step)  # no orphan: the step died with its template
    _consistent(project.store)
    _verify_ok(project, capsys)
    assert list((project.store / "tmp").iterdir()) == []
    s = project.run_json("--set", "upper.mode=title", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "ran"}


def test_runner_killed_at_random_moments(project, capsys):
    rng = random.Random(0)
    for i in range(4):
        proc = project.proc("run", "p", "--set", f"gen.n={3 + i}", "--set", "gen.sleep=0.05")
        time.sleep(rng.uniform(0.0, 1.0))
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        _consistent(project.store)
    s = project.run_json("--set", "gen.n=6", "--set", "gen.sleep=0.05", capsys=capsys)
    assert s["ok"] and set(project.how(s).values()) <= {"ran", "cached", "cut off"}
    _verify_ok(project, capsys)


@LAUNCH
def test_sigterm_stops_cleanly(project, capsys, launch):
    proc = project.proc("run", "p", "--set", "upper.sleep=30", *launch)
    step = _wait_for_step(project, proc, "upper")
    others = [pid for pid, _, _ in _descendants(proc.pid)]
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 130 and "completed steps are kept" in err
    for pid in [step, *others]:
        _wait_dead(pid)
    assert list((project.store / "tmp").iterdir()) == []
    s = project.run_json(capsys=capsys)
    assert project.how(s)["gen"] == "cached"


def test_two_concurrent_runs(project, capsys):
    a = project.proc("run", "p", "--set", "upper.sleep=1")
    time.sleep(0.3)
    b = project.proc("run", "p", "--set", "upper.sleep=1")
    out_a, err_a = a.communicate(timeout=60)
    out_b, err_b = b.communicate(timeout=60)
    assert a.returncode == 0 and b.returncode == 0, (err_a, err_b)
    assert "locked by pid" in err_a + err_b and "waiting" in err_a + err_b
    assert "3 cached" in out_b or "3 cached" in out_a
    _consistent(project.store)


def test_lock_timeout(project, capsys):
    a = project.proc("run", "p", "--set", "upper.sleep=5")
    _wait_for_step(project, a, "upper")
    rc, out, err = project.cli("run", "p", "--lock-timeout", "0.2", capsys=capsys)
    assert rc == 2 and "still locked" in err and len(err.strip().splitlines()) == 2
    a.kill()
    a.wait()


def test_corrupted_object_is_detected_and_recomputed(project, capsys):
    s = project.run_json("p", capsys=capsys)
    digest = s["stages"]["upper"]["outputs"]["text.txt"]
    obj = project.store / "objects" / digest[:2] / digest
    os.chmod(obj, 0o644)
    obj.write_text("garbage")
    s = project.run_json(capsys=capsys)
    _, err = capsys.readouterr()
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "cut off"}
    assert s["stages"]["upper"]["outputs"]["text.txt"] == digest
    assert hashlib.sha256(obj.read_bytes()).hexdigest() == digest
    assert any((project.store / "corrupt").iterdir())


def test_verify_finds_corruption_hidden_from_stat(project, capsys):
    s = project.run_json("p", capsys=capsys)
    digest = s["stages"]["gen"]["outputs"]["text.txt"]
    obj = project.store / "objects" / digest[:2] / digest
    st = obj.stat()
    data = bytearray(obj.read_bytes())
    data[0] ^= 1
    os.chmod(obj, 0o644)
    obj.write_bytes(bytes(data))
    os.utime(obj, ns=(st.st_atime_ns, st.st_mtime_ns))  # same size, same mtime
    rc, out, _ = project.cli("verify", capsys=capsys)
    assert rc == 1 and f"corrupt object {digest}" in out
    s = project.run_json(capsys=capsys)
    assert project.how(s)["gen"] == "ran"
    _verify_ok(project, capsys)

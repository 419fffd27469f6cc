"""Warm starts (holoflow/flow/executors/warm.py): a forked step behaves as an exec'd one, and a template
survives its children's crashes."""

import json
import os
import signal
import time
from pathlib import Path

import pytest

from holoflow.flow.executors import warm
from holoflow.flow.executors.task import step_env  # the function (the package attribute may be the module)
from holoflow.flow.executors.warm import Launcher, first_use, preload, supported

pytestmark = pytest.mark.skipif(not supported(), reason="warm starts need Linux pidfds")

PROBE = """import json, os, sys
print(json.dumps({"argv": sys.argv, "cwd": os.getcwd(), "path0": sys.path[0], "pid": os.getpid(),
                  "omp": os.environ.get("OMP_NUM_THREADS"), "stage": os.environ.get("HOLOFLOW_STAGE"),
                  "numpy": "numpy" in sys.modules, "holoflow": [m for m in sys.modules if m.startswith("holoflow")],
                  "helper": __import__("helper").X}))
"""


@pytest.fixture
def launcher():
    warm = Launcher()
    yield warm
    warm.close()


def _run(launcher, program: Path, cpus: int = 1, **extra):
    env = dict(os.environ, HOLOFLOW_STAGE=program.stem, **step_env({"cpus": cpus}), **extra)
    step = launcher.start(str(program), "job.json", str(program.parent), env)
    out = step.stdout.read().decode()
    step.stdout.close()
    status, usage = step.wait4()
    return step, os.waitstatus_to_exitcode(status), out, usage


def test_child_runs_like_a_script_with_fresh_project_code(tmp_path, launcher):
    (tmp_path / "probe.py").write_text(PROBE)
    (tmp_path / "helper.py").write_text("X = 1\n")
    launcher.ensure(step_env({"cpus": 1}), ["numpy", "json"])
    step, code, out, usage = _run(launcher, tmp_path / "probe.py")
    seen = json.loads(out)
    assert code == 0 and seen["pid"] == step.pid != os.getpid()
    assert seen["argv"] == [str(tmp_path / "probe.py"), "job.json"] and seen["cwd"] == str(tmp_path)
    assert seen["path0"] == str(tmp_path) and seen["stage"] == "probe" and seen["omp"] == "1"
    assert seen["numpy"] and seen["holoflow"] == []  # heavy modules preloaded; the project's not
    assert usage.ru_maxrss > 0
    (tmp_path / "helper.py").write_text("X = 2\n")  # edited between two steps: the next sees it
    assert json.loads(_run(launcher, tmp_path / "probe.py")[2])["helper"] == 2


def test_threads_come_from_the_template_of_the_steps_cpus(tmp_path, launcher):
    (tmp_path / "probe.py").write_text(PROBE)
    (tmp_path / "helper.py").write_text("X = 1\n")
    two = step_env({"cpus": 2})
    launcher.ensure(step_env({"cpus": 1}), [])
    launcher.ensure(two, [])
    assert json.loads(_run(launcher, tmp_path / "probe.py", cpus=2)[2])["omp"] == two["OMP_NUM_THREADS"]


@pytest.mark.parametrize(
    "body, code, text",
    [
        ("raise SystemExit(3)", 3, ""),
        ("import sys; sys.exit('probe: bad input')", 1, "probe: bad input"),
        ("raise RuntimeError('boom')", 1, "RuntimeError: boom"),
        ("import os, signal; os.kill(os.getpid(), signal.SIGSEGV)", -signal.SIGSEGV, ""),
        ("import atexit; atexit.register(print, 'at exit')", 0, "at exit"),
    ],
)
def test_a_crashing_step_leaves_the_template_serving(tmp_path, launcher, body, code, text):
    (tmp_path / "bad.py").write_text(body + "\n")
    (tmp_path / "ok.py").write_text("print('fine')\n")
    launcher.ensure(step_env({"cpus": 1}), [])
    _, got, out, _ = _run(launcher, tmp_path / "bad.py")
    assert got == code and text in out
    _, got, out, _ = _run(launcher, tmp_path / "ok.py")
    assert got == 0 and out == "fine\n"


def test_killed_template_takes_its_steps_along(tmp_path, launcher):
    (tmp_path / "slow.py").write_text("import time\nprint('up', flush=True)\ntime.sleep(60)\n")
    launcher.ensure(step_env({"cpus": 1}), [])
    env = dict(os.environ, **step_env({"cpus": 1}))
    step = launcher.start(str(tmp_path / "slow.py"), "job.json", str(tmp_path), env)
    assert step.stdout.readline() == b"up\n"
    template = launcher._templates[env["OMP_NUM_THREADS"]].proc
    template.kill()
    template.wait()
    assert step.stdout.read() == b""  # EOF: the step is gone
    status, _ = step.wait4()
    assert step.lost and os.waitstatus_to_exitcode(status) == -signal.SIGKILL
    deadline = time.monotonic() + 10
    while _alive(step.pid):
        assert time.monotonic() < deadline, "step outlived its template"
        time.sleep(0.02)
    launcher.ensure(step_env({"cpus": 1}), [])  # a dead template is replaced
    (tmp_path / "ok.py").write_text("print('fine')\n")
    assert _run(launcher, tmp_path / "ok.py")[1] == 0


def test_kill_reaches_the_step(tmp_path, launcher):
    (tmp_path / "slow.py").write_text("import time\nprint('up', flush=True)\ntime.sleep(60)\n")
    launcher.ensure(step_env({"cpus": 1}), [])
    step = launcher.start(
        str(tmp_path / "slow.py"), "job.json", str(tmp_path), dict(os.environ, **step_env({"cpus": 1}))
    )
    assert step.stdout.readline() == b"up\n"
    step.kill()
    assert step.stdout.read() == b""
    status, _ = step.wait4()
    assert os.waitstatus_to_exitcode(status) == -signal.SIGKILL and not step.lost


def _alive(pid):
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_preload_keeps_heavy_third_party_modules_only():
    assert preload(["torch.nn", "numpy", "json", "diffusers", "holoflow.stage"]) == ["numpy", "torch.nn"]
    assert first_use(["torch.optim", "numpy"]) == ["torch._dynamo"] and first_use(["torch"]) == []


def test_template_imports_first_use_modules_while_it_waits(tmp_path, launcher, monkeypatch):
    (tmp_path / "slow_first_use.py").write_text(f"open({str(tmp_path / 'imported')!r}, 'w').close()\n")
    (tmp_path / "probe.py").write_text("import sys; print('slow_first_use' in sys.modules)\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    monkeypatch.setitem(warm.ON_FIRST_USE, "json", ("slow_first_use",))
    launcher.ensure(step_env({"cpus": 1}), ["json"])
    deadline = time.monotonic() + 30
    while not (tmp_path / "imported").exists():  # imported before any step asked for it
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert _run(launcher, tmp_path / "probe.py")[2].strip() == "True"


def test_step_env_sets_threads_and_a_bounded_spin(monkeypatch):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    env = step_env({"cpus": 1})
    assert env["OMP_NUM_THREADS"] == env["NUMBA_NUM_THREADS"] == "1" and env["GOMP_SPINCOUNT"] == "30000"
    assert "OMP_WAIT_POLICY" not in env
    monkeypatch.setenv("GOMP_SPINCOUNT", "1000")
    assert step_env({"cpus": 1})["GOMP_SPINCOUNT"] == "1000"
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")  # the user's policy wins
    env = step_env({"cpus": 1})
    assert env["OMP_WAIT_POLICY"] == "PASSIVE" and "GOMP_SPINCOUNT" not in env
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    assert step_env({"cpus": 1})["OMP_WAIT_POLICY"] == "ACTIVE"

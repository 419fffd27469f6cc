"""Run one step as its own process and commit its outputs: the worker side of every executor.

``run_step(task)`` stages a job folder under the store's tmp/, starts ``[python, PROGRAM, JOB.json]``
(or ``[PROGRAM, JOB.json]``) without a shell, keeps its output as the log, and after exit 0 moves each
output into objects/ and writes the key record last (docs/store.md). It runs in a thread of the driver
(local executor) or inside a Ray task on any host that mounts the store at the same path; the result
is plain data either way. A killed step (or a killed worker) leaves only staging in tmp/.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from holoflow import __version__

from ..store import Store, remove_tree
from .failure import exit_reason, store_problem
from .step_env import PINNED_ENV, cpu_facts
from .task import StepTask, step_env

LOG_TAIL = 15


def run_step(
    task: StepTask,
    executor: str = "local",
    on_line: Callable[[str], None] | None = None,
    started: Callable[[Any], None] | None = None,
    aborted: Callable[[], bool] | None = None,
    launcher=None,
) -> dict[str, Any]:
    """Run ``task``'s program; on exit 0 commit outputs + record. Returns {ok, record | reason, log, tail}.

    ``on_line`` gets each output line (progress, meta, log); ``started`` the process once it runs (it
    has ``pid`` and ``kill()``); ``aborted()`` true means the run was stopped: nothing is committed and
    no failed log is kept. With a ``launcher`` (holoflow.flow.executors.warm) a Python program is forked
    from a warm template instead of exec'd. Three steps: launch, validate the outputs, commit. A store
    that refuses writes (full, read-only) is a failed result with ``store_error`` set; the record is
    written last, so nothing half-committed is seen.
    """
    try:
        return _run_step(task, executor, on_line, started, aborted, launcher)
    except OSError as e:
        why = store_problem(e)
        if why is None:
            raise
        return {"ok": False, "host": platform.node(), "reason": why, "tail": "", "store_error": True}


def _run_step(task: StepTask, executor: str, on_line, started, aborted, launcher) -> dict[str, Any]:
    store = Store(task.store)
    staging = store.staging(task.stage)
    run = _launch(task, staging, on_line, started, launcher)
    host = platform.node()
    if aborted and aborted():
        remove_tree(staging)
        return {"ok": False, "aborted": True, "host": host, "reason": "stopped"}
    files, failure = _validate(run)
    if failure is not None:
        kept = _keep_failed_log(store, task, run.log_path)
        remove_tree(staging)
        return {"ok": False, "host": host, **failure, "log": str(kept), "tail": _tail(kept, LOG_TAIL)}
    rec = store.write_record(_record(store, task, run, files, executor, host), replace=task.replace)  # first wins
    remove_tree(staging)
    return {"ok": True, "record": rec, "host": host}


@dataclass
class _Launched:
    """A finished step process: its output folder and log, exit code, resource use, @meta lines."""

    out_dir: Path
    log_path: Path
    argv0: str
    warm: bool
    code: int
    usage: Any  # os.wait4's resource use
    meta: dict[str, Any]
    t_start: float  # time.time() at the launch
    wall: float  # seconds
    lost: bool  # its warm template died under it


def _launch(task: StepTask, staging: Path, on_line, started, launcher) -> _Launched:
    """Write the job spec into ``staging``, start the program (exec'd, or forked from ``launcher``'s warm
    template), stream its output to the log and ``on_line``, and wait for it. A failure to start or
    an interruption removes ``staging`` and raises."""
    out_dir, work_dir = staging / "out", staging / "work"
    out_dir.mkdir()
    work_dir.mkdir()
    job = staging / "job.json"
    job.write_text(
        json.dumps({**task.spec, "output_dir": str(out_dir), "work_dir": str(work_dir)}, indent=1, sort_keys=True)
    )
    program = Path(task.program)
    python = program.suffix == ".py"
    argv = [sys.executable, str(program), str(job)] if python else [str(program), str(job)]
    env = dict(os.environ, PYTHONUNBUFFERED="1", HOLOFLOW_STAGE=task.stage, **step_env(task.resources), **task.env)
    env.pop("RAY_AUTH_TOKEN", None)  # a Ray cluster's secret: a step has no use for it
    warm = launcher is not None and python
    log_path = staging / "log.txt"
    meta: dict[str, Any] = {}
    t_start = time.time()
    t0 = time.monotonic()
    with open(log_path, "wb") as log:
        try:
            proc = launcher.start(str(program), str(job), task.cwd, env) if warm else ExecStep(argv, task.cwd, env)
        except BaseException:
            remove_tree(staging)
            raise
        try:
            if started:
                started(proc)
            for raw in proc.stdout:
                log.write(raw)
                line = raw.decode(errors="replace").rstrip("\n")
                if line.startswith("@meta "):
                    m = _json_or_none(line[6:])
                    if isinstance(m, dict):
                        meta.update(m)
                if on_line:
                    on_line(line)
            status, usage = proc.wait4()
            code = os.waitstatus_to_exitcode(status)
        except BaseException:
            proc.kill()
            proc.wait4()
            remove_tree(staging)
            raise
        finally:
            proc.stdout.close()
    return _Launched(
        out_dir,
        log_path,
        Path(argv[0]).name,
        warm,
        code,
        usage,
        meta,
        t_start,
        time.monotonic() - t0,
        getattr(proc, "lost", False),
    )


def _validate(run: _Launched) -> tuple[list[Path], dict[str, Any] | None]:
    """(the output files, None) when the step exited 0 and wrote at least one output, all regular
    files; else ([], the failure: {reason}, plus ``bad_output`` when the program itself is at fault and
    no retry helps)."""
    if run.code != 0:
        reason = exit_reason(run.code, _tail(run.log_path, LOG_TAIL))
        return [], {"reason": reason + (" (its warm template died)" if run.lost else "")}
    files = sorted(p for p in run.out_dir.rglob("*") if not p.is_dir())
    bad = [p for p in files if p.is_symlink() or not p.is_file()]
    if bad or not files:
        what = f"wrote a non-regular file {bad[0].relative_to(run.out_dir)}" if bad else "wrote no output files"
        return [], {"reason": what, "bad_output": True}
    return files, None


def _record(
    store: Store, task: StepTask, run: _Launched, files: list[Path], executor: str, host: str
) -> dict[str, Any]:
    """Hash the output ``files`` and the log into the store's objects; the step's key record (docs/store.md)."""
    committed = {p.relative_to(run.out_dir).as_posix(): store.put(p) for p in files}
    log_entry = store.put(run.log_path)
    meta, usage = run.meta, run.usage
    versions = {"python": platform.python_version(), "holoflow": __version__, "platform": platform.platform()}
    versions.update(meta.pop("versions", {}) if isinstance(meta.get("versions"), dict) else {})
    if "torch" in meta:
        versions["torch"] = meta["torch"]
    pinned = {**step_env(task.resources), **task.env}  # what the step's environment held
    return {
        "key": task.key,
        "stage": task.stage,
        "components": task.components,
        "outputs": committed,
        "provenance": {
            **task.provenance,
            "argv0": run.argv0,
            "meta": meta,
            "versions": versions,
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(run.t_start)),
            "wall_s": round(run.wall, 3),
            "cpu_s": round(usage.ru_utime + usage.ru_stime, 3),
            "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
            "exit_code": run.code,
            "log": log_entry["digest"],
            "log_size": log_entry["size"],
            "host": host,
            "cpu": {**cpu_facts(), **{k: pinned[k] for k in PINNED_ENV}},
            "executor": executor,
            "launch": "warm" if run.warm else "cold",
            "attempt": task.attempt,
            "resources": {
                **task.resources,
                **({"gpu_ids": task.env["CUDA_VISIBLE_DEVICES"]} if "CUDA_VISIBLE_DEVICES" in task.env else {}),
            },
        },
    }


class ExecStep:
    """A step exec'd as its own program (``[python,] PROGRAM JOB.json``, no shell), dying with its
    starter (PR_SET_PDEATHSIG)."""

    def __init__(self, argv: list[str], cwd: str, env: dict[str, str]):
        self._proc = popen(
            argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, cwd=cwd, env=env
        )
        self.pid, self.stdout = self._proc.pid, self._proc.stdout

    def kill(self) -> None:
        self._proc.kill()

    def wait4(self):
        """(wait status, resource use) of the finished step."""
        _, status, usage = os.wait4(self.pid, 0)
        self._proc.returncode = os.waitstatus_to_exitcode(status)
        return status, usage


def popen(argv: list[str], **kw) -> subprocess.Popen:
    """``subprocess.Popen`` (no shell) of a process that dies with the thread that started it."""
    prctl = _prctl()
    return subprocess.Popen(argv, preexec_fn=(lambda: prctl(1, signal.SIGKILL)) if prctl else None, **kw)


def _prctl():
    """libc prctl, resolved in the parent: the child only calls it (no imports between fork and exec)."""
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6", use_errno=True).prctl
    except OSError:
        return None


def _keep_failed_log(store: Store, task: StepTask, log_path: Path) -> Path:
    again = f".attempt{task.attempt}" if task.attempt > 1 else ""
    dest = store.root / "logs" / f"{task.spec.get('run')}-{task.label.replace('/', '-')}{again}.log"
    dest.parent.mkdir(exist_ok=True)
    shutil.copyfile(log_path, dest)
    return dest


def _tail(path: Path, n: int) -> str:
    lines = [ln for ln in path.read_text(errors="replace").splitlines() if not ln.startswith("@progress ")]
    return "\n".join(lines[-n:]) if lines else "(the step printed nothing)"


def _json_or_none(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return None

"""Warm starts for the local executor: Python steps forked from a template that imported the heavy
modules once per run (holoflow.flow.executors.template), instead of each paying for ``import torch``.

A run has one template per thread count (a step's ``resources.cpus``, capped at the host's cores):
the thread variables are in the template's environment when the libraries load, as they would be in
a cold step. A template preloads only third-party modules (:data:`HEAVY`) that the steps' import
closures name; the project's own modules load fresh in each child, so a step runs the code its cache
key hashed. Templates are started from the run's scheduling thread (PR_SET_PDEATHSIG follows the
thread that started a process) and stop when the run closes its executor or dies.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from types import SimpleNamespace

from ..code_closure import HOLOFLOW_ROOT
from .step import popen

#: third-party modules worth importing once per run (torch alone takes seconds)
HEAVY = frozenset({"torch", "numpy", "scipy", "kornia", "numba", "cv2", "OpenImageIO", "OpenEXR", "plyfile"})
#: what a module loads on first use rather than at import: torch's optimisers import torch._dynamo in
#: their constructor (a cost every training step would pay). A template imports
#: these while it waits for its first step (template.serve's ``idle``)
ON_FIRST_USE = {"torch.optim": ("torch._dynamo",)}


def supported() -> bool:
    """Warm starts need fork, descriptor passing and pidfds (Linux)."""
    return sys.platform.startswith("linux") and hasattr(os, "pidfd_open") and hasattr(socket, "send_fds")


def preload(modules: list[str]) -> list[str]:
    """The :data:`HEAVY` ones among a step's external imports."""
    return sorted(m for m in modules if m.partition(".")[0] in HEAVY)


def first_use(modules: list[str]) -> list[str]:
    """What the step's external imports load on first use (:data:`ON_FIRST_USE`)."""
    return sorted({x for m in modules for x in ON_FIRST_USE.get(m, ())})


class WarmStep:
    """A step forked by a template, seen through the calls run_step makes on a cold one."""

    def __init__(self, chan: socket.socket, stdout, pid: int):
        self._chan, self.stdout, self.pid = chan, stdout, pid
        self.lost = False  # the template vanished before reporting the exit

    def kill(self) -> None:
        try:
            self._chan.send(b"kill")
        except OSError:
            pass  # already reaped (the template closed the channel)

    def wait4(self) -> tuple[int, SimpleNamespace]:
        """(wait status, resource use) of the child, as the template reaped it."""
        try:
            msg = self._chan.recv(4096)
        finally:
            self._chan.close()
        if not msg:  # the template died; PR_SET_PDEATHSIG killed the child
            self.lost = True
            return signal.SIGKILL, SimpleNamespace(ru_utime=0.0, ru_stime=0.0, ru_maxrss=0)
        r = json.loads(msg)
        return r["status"], SimpleNamespace(ru_utime=r["utime"], ru_stime=r["stime"], ru_maxrss=r["maxrss"])


class _Template:
    def __init__(self, threads_env: dict[str, str], modules: list[str], idle: list[str]):
        self.control, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        env = dict(os.environ, PYTHONUNBUFFERED="1", **threads_env)
        argv = [str(theirs.fileno()), *modules, *(["--idle", *idle] if idle else [])]
        with theirs:
            self.proc = popen(
                [sys.executable, "-m", "holoflow.flow.executors.template", *argv],
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                cwd=HOLOFLOW_ROOT,
                env=env,
            )

    def alive(self) -> bool:
        return self.proc.poll() is None

    def fork(self, program: str, job: str, cwd: str, env: dict[str, str]) -> WarmStep:
        read, write = os.pipe()
        mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            req = json.dumps({"program": program, "job": job, "cwd": cwd, "env": env}).encode()
            socket.send_fds(self.control, [req], [theirs.fileno(), write])
        except OSError:
            os.close(read)
            mine.close()
            raise
        finally:
            theirs.close()
            os.close(write)
        stdout = open(read, "rb")
        msg = mine.recv(4096)
        step = WarmStep(mine, stdout, json.loads(msg)["pid"] if msg else -1)
        if not msg:  # the template died before forking: no child, no output
            step.lost = True
        return step

    def close(self) -> None:
        self.control.close()  # the template returns when its control socket closes
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class Launcher:
    """The templates of one run, keyed by thread count."""

    def __init__(self):
        self._templates: dict[str, _Template] = {}

    def ensure(self, threads_env: dict[str, str], modules: list[str]) -> None:
        """Start the template for ``threads_env`` (preloading ``modules``) unless one is running.
        Call it from the thread that lives as long as the run."""
        n = threads_env.get("OMP_NUM_THREADS", "1")
        t = self._templates.get(n)
        if t is None or not t.alive():
            self._templates[n] = _Template(threads_env, preload(modules), first_use(modules))

    def start(self, program: str, job: str, cwd: str, env: dict[str, str]) -> WarmStep:
        """Fork ``python PROGRAM JOB`` from the template of ``env``'s thread count (ensured before)."""
        return self._templates[env.get("OMP_NUM_THREADS", "1")].fork(program, job, cwd, env)

    def close(self) -> None:
        for t in self._templates.values():
            t.control.close()  # every template leaves at once, then each is reaped
        for t in self._templates.values():
            t.close()
        self._templates.clear()

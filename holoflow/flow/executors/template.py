"""The warm template: a process that imports heavy modules once and forks one child per step.

Started by holoflow.flow.executors.warm as ``python -m holoflow.flow.executors.template CONTROL_FD MODULE...
[--idle MODULE...]``
with the thread variables of one ``resources.cpus`` value already in its environment (so every
library reads the same thread counts at import as a cold step would). It imports the modules named,
starts nothing parallel (no torch op, no numba kernel; OpenBLAS stops its idle pool before each fork
itself), then serves requests from the control socket, one at a time:

- a request is ``{program, job, cwd, env}`` with two file descriptors: the step's channel (a
  SOCK_SEQPACKET socket back to the runner) and the write end of its output pipe;
- the template forks; the child runs the program as ``python PROGRAM JOB.json`` would (:func:`_child`);
- the template answers ``{"pid": N}`` on the channel, and ``{"status", "utime", "stime", "maxrss"}``
  once it has reaped the child (its own wait4: exit code and resource use are the child's alone);
  ``kill`` on the channel (or the runner closing it) SIGKILLs the child, which is not yet reaped.

Every child dies with the template (PR_SET_PDEATHSIG), the template with the runner (the same, set
by the runner) and when the control socket closes. A crashing child never takes the template down.
"""

from __future__ import annotations

import ctypes
import importlib
import json
import os
import selectors
import signal
import socket
import sys

PR_SET_NAME, PR_SET_PDEATHSIG = 15, 1


def serve(control_fd: int, modules: list[str], idle: list[str] = ()) -> None:
    """Import ``modules`` (those installed), then fork children for requests until the runner leaves.
    ``idle`` modules are imported one at a time until the first request arrives: a template started
    ahead of its steps (``LocalExecutor.expect``) loads them off the run's critical path, one whose
    step is already waiting does not make it wait longer (its steps import them when they need them)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the runner, which stops us
    for name in modules:
        _import(name)
    idle = list(idle)
    libc = ctypes.CDLL(None, use_errno=True)
    control = socket.socket(fileno=control_fd)
    sel = selectors.DefaultSelector()
    sel.register(control, selectors.EVENT_READ, "control")
    steps: dict[int, tuple[socket.socket, int]] = {}  # pid -> (channel, pidfd)
    while True:
        events = sel.select(0 if idle else None)
        if not events and idle:
            _import(idle.pop(0))
            continue
        for key, _ in events:
            if key.data == "control":
                idle.clear()
                msg, fds, _, _ = socket.recv_fds(control, 1 << 20, 2)
                if not msg:
                    for pid in steps:
                        _kill(pid)
                    return
                chan, out = socket.socket(fileno=fds[0]), fds[1]
                owned = [control.fileno(), sel.fileno(), *(fd for c, p in steps.values() for fd in (c.fileno(), p))]
                pid = os.fork()
                if pid == 0:
                    _child(json.loads(msg), out, [*owned, chan.fileno()], libc)
                os.close(out)
                pidfd = os.pidfd_open(pid)
                steps[pid] = (chan, pidfd)
                sel.register(chan, selectors.EVENT_READ, ("chan", pid))
                sel.register(pidfd, selectors.EVENT_READ, ("exit", pid))
                _send(chan, {"pid": pid})
            elif key.data[0] == "chan":
                try:
                    key.fileobj.recv(64)  # "kill", or b"" when the runner closed it
                except OSError:
                    pass
                _kill(key.data[1])
                sel.unregister(key.fileobj)
            else:
                pid = key.data[1]
                chan, pidfd = steps.pop(pid)
                _, status, usage = os.wait4(pid, 0)
                sel.unregister(pidfd)
                os.close(pidfd)
                if chan.fileno() in sel.get_map():
                    sel.unregister(chan)
                _send(
                    chan,
                    {"status": status, "utime": usage.ru_utime, "stime": usage.ru_stime, "maxrss": usage.ru_maxrss},
                )
                chan.close()


def _import(name: str) -> None:
    try:
        importlib.import_module(name)
    except ImportError:
        pass  # not installed here: a step that needs it fails on its own


def _child(req: dict, out: int, inherited: list[int], libc) -> None:
    """In the forked child: become the step (``python PROGRAM JOB.json``) and exit with its code."""
    code = 1
    try:
        parent = os.getppid()
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # the template died before the line above
            os._exit(1)
        program = req["program"]
        libc.prctl(PR_SET_NAME, os.path.basename(program).encode()[:15])
        for fd in inherited:
            os.close(fd)
        os.dup2(out, 1)
        os.dup2(out, 2)
        os.close(out)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        for name in [m for m in sys.modules if m == "holoflow" or m.startswith("holoflow.")]:
            del sys.modules[name]  # the project's modules load fresh from disk, as the key says
        sys.argv = [program, req["job"]]
        sys.path[0] = os.path.dirname(program)
        code = _run(program)
    except BaseException:
        import traceback

        traceback.print_exc()  # becoming the step failed: say why in its log
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)


def _run(program: str) -> int:
    """Run ``program`` as ``__main__`` with a fresh atexit list; its exit code as Python would give it."""
    import atexit
    import runpy
    import traceback

    atexit._clear()
    try:
        runpy.run_path(program, run_name="__main__")
        code = 0
    except SystemExit as e:
        code = _exit_code(e.code)
    except BaseException:
        traceback.print_exc()
        code = 1
    atexit._run_exitfuncs()
    return code


def _exit_code(value) -> int:
    """What ``sys.exit(value)`` makes the process exit with (a message is printed, code 1)."""
    if value is None:
        return 0
    if isinstance(value, int):
        return value & 0xFF
    print(value, file=sys.stderr)
    return 1


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _send(chan: socket.socket, payload: dict) -> None:
    try:
        chan.send(json.dumps(payload).encode())
    except OSError:
        pass  # the runner gave up on this step


if __name__ == "__main__":
    args = sys.argv[2:]
    cut = args.index("--idle") if "--idle" in args else len(args)
    serve(int(sys.argv[1]), args[:cut], args[cut + 1 :])
    os._exit(0)  # nothing to flush or clean up: skip tearing down torch & co (the run waits on it)

"""The local executor: steps run as processes on this machine, up to ``-j N`` CPU slots at once.

Each step takes ``min(cpus, N)`` CPU slots, ``gpus`` whole GPUs (exported to it as
CUDA_VISIBLE_DEVICES, so two GPU steps never share a GPU) and ``memory_gb`` of this host's memory;
a step that asks for more than the machine has is clamped so it still runs (alone). GPUs count only
for ``--device cuda``: on a CPU run every step is a CPU step. Each running step is watched by one
thread; results come back through a queue read by the runner's (main) thread. Python steps start
warm (forked from a template that imported the heavy modules once, holoflow/flow/executors/warm.py) unless
``warm`` is off (``--cold``) or the platform lacks what it needs.
"""

from __future__ import annotations

import queue
import threading
from typing import Any

from ..code_closure import HOLOFLOW_ROOT
from . import ahead as ahead_mod
from .step import run_step
from .task import StepTask, gpu_ids, host_memory_gb, step_env


class LocalExecutor:
    kind = "local"
    default_retries = 0

    def __init__(self, jobs: int = 1, device: str = "cpu", on_line=None, warm: bool = True):
        self.jobs = max(1, int(jobs))
        self.gpus = gpu_ids() if device == "cuda" else []
        self.memory_gb = host_memory_gb()
        self.free_cpus = self.jobs
        self.free_gpus = list(self.gpus)
        self.free_memory = self.memory_gb
        self.on_line = on_line
        self._events: queue.Queue = queue.Queue()
        self._procs: dict[int, Any] = {}
        self._threads: dict[int, threading.Thread] = {}
        self._held: dict[int, tuple[int, list[str], float]] = {}
        self._next = 0
        self._aborted = False
        self.launcher = None
        self.ahead = None  # the compile-ahead process, once started
        if warm:
            from . import warm as warm_mod

            self.launcher = warm_mod.Launcher() if warm_mod.supported() else None

    def describe(self) -> str:
        gpus = f", {len(self.gpus)} GPU" if self.gpus else ""
        return f"local, -j {self.jobs}{gpus}, {'warm' if self.launcher else 'cold'}"

    def expect(self, needs: list[tuple[dict[str, Any], list[str]]], ahead: list[str] = ()) -> None:
        """Steps still to come, as (resources, external imports): start their warm templates now, so
        their imports overlap the steps before them, and the compiling of the numba kernels of
        ``ahead`` (holoflow/flow/executors/ahead.py). Call it from the run's scheduling thread."""
        if self.ahead is None:
            self.ahead = ahead_mod.start(list(ahead), HOLOFLOW_ROOT)
        if self.launcher is None:
            return
        by_threads: dict[tuple, tuple[dict[str, str], set[str]]] = {}
        for res, modules in needs:
            env = step_env(res)
            by_threads.setdefault(tuple(sorted(env.items())), (env, set()))[1].update(modules)
        for env, modules in by_threads.values():
            self.launcher.ensure(env, sorted(modules))

    def request(self, res: dict[str, Any]) -> tuple[int, int, float]:
        """(cpu slots, gpus, memory GiB) a step with declared ``res`` takes here (clamped to the host)."""
        cpus = min(max(1, int(res.get("cpus", 1))), self.jobs)
        gpus = min(int(res.get("gpus", 0)), len(self.gpus))
        mem = min(float(res.get("memory_gb", 0.0)), self.memory_gb)
        return cpus, gpus, mem

    def fits(self, res: dict[str, Any]) -> bool:
        cpus, gpus, mem = self.request(res)
        return cpus <= self.free_cpus and gpus <= len(self.free_gpus) and mem <= self.free_memory + 1e-9

    def running(self) -> int:
        return len(self._threads)

    def submit(self, task: StepTask) -> int:
        cpus, gpus, mem = self.request(task.resources)
        taken = self.free_gpus[:gpus]
        self.free_gpus = self.free_gpus[gpus:]
        self.free_cpus -= cpus
        self.free_memory -= mem
        if self.gpus and task.resources.get("gpus", 0):
            task.env["CUDA_VISIBLE_DEVICES"] = ",".join(taken)
        handle = self._next
        self._next += 1
        self._held[handle] = (cpus, taken, mem)
        if self.launcher is not None and task.program.endswith(".py"):
            self.launcher.ensure(step_env(task.resources), task.modules)
        t = threading.Thread(target=self._work, args=(handle, task), name=f"holoflow-{task.label}", daemon=True)
        self._threads[handle] = t
        t.start()
        return handle

    def _work(self, handle: int, task: StepTask) -> None:
        def line(text: str) -> None:
            self._events.put(("line", handle, (task.label, text)))

        def started(proc) -> None:
            self._procs[handle] = proc
            if self._aborted:
                proc.kill()

        try:
            result = run_step(
                task,
                "local",
                on_line=line if self.on_line else None,
                started=started,
                aborted=lambda: self._aborted,
                launcher=self.launcher,
            )
        except BaseException as e:  # a bug or an OS error in the runner side: report, don't hang
            result = {"ok": False, "reason": f"{type(e).__name__}: {e}", "tail": ""}
        self._events.put(("done", handle, result))

    def wait(self, timeout: float | None = None) -> list[tuple[int, dict]]:
        """Results of finished steps (at least one unless ``timeout`` passes); forwards output lines."""
        done = []
        block = True
        while True:
            try:
                kind, handle, payload = self._events.get(block=block, timeout=timeout if block else None)
            except queue.Empty:
                return done
            if kind == "line":
                if self.on_line:
                    self.on_line(*payload)
            else:
                self._release(handle)
                done.append((handle, payload))
            block = not done

    def _release(self, handle: int) -> None:
        cpus, taken, mem = self._held.pop(handle)
        self.free_cpus += cpus
        self.free_gpus = sorted(self.free_gpus + taken, key=lambda g: self.gpus.index(g))
        self.free_memory += mem
        self._procs.pop(handle, None)
        self._threads.pop(handle).join()

    def abort(self) -> None:
        """Kill every running step and wait until their staging is removed."""
        self._aborted = True
        for proc in list(self._procs.values()):
            try:
                proc.kill()
            except OSError:
                pass
        while self._threads:
            self.wait(timeout=None)

    def close(self) -> None:
        if self._threads:
            self.abort()
        if self.launcher is not None:
            self.launcher.close()
        if self.ahead is not None:  # what it compiled is in numba's cache; the rest waits
            self.ahead.kill()
            self.ahead.wait()

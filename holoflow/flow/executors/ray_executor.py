"""The Ray executor: one Ray task per step, each requesting its stage's declared resources.

The task (``_ray_step``) calls holoflow.flow.executors.step.run_step on whichever node Ray picks, so the
step is still its own OS process (a child of the Ray worker), and it commits into the shared store
itself. Requests: ``num_cpus = min(cpus, the largest node's CPUs)``, ``num_gpus = gpus`` when the run
is ``--device cuda`` and the cluster has GPUs (Ray then sets CUDA_VISIBLE_DEVICES for the task, which
the step inherits), ``memory = memory_gb`` (clamped to the cluster's). Ray's own task retries are off:
the runner retries a failed step itself (a dead worker reads as a failure "worker lost"), so every
attempt is counted and logged the same way as with the local executor.

Joining an existing cluster (``--address``): its token and a bounded wait, holoflow.flow.executors.ray_connect.
Requires the ``ray`` extra (``pip install -e '.[ray]'``); docs/scale.md has the cluster set-up.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from .ray_connect import CONNECT_TIMEOUT_S, held_stderr, join_failed, use_token, wait_for_cluster
from .task import StepTask


def _ray_step(task: StepTask) -> dict:
    from .step import run_step

    return run_step(task, "ray")


class RayExecutor:
    kind = "ray"
    default_retries = 2

    def __init__(
        self, address: str | None = None, jobs: int = 1, device: str = "cpu", connect_timeout: float = CONNECT_TIMEOUT_S
    ):
        token = use_token(address)  # before Ray reads its config: it decides whether to send one
        try:
            import ray
        except ImportError:
            from ..pipeline import PipelineError

            raise PipelineError("--executor ray needs Ray; fix: pip install -e '.[ray]' (ray>=2.30)") from None
        self.ray = ray
        if address and not ray.is_initialized():
            wait_for_cluster(address, connect_timeout)
        # Ray's driver prints worker-death notices on stdout; keep stdout for --json (restored on close)
        self._stdout, sys.stdout = sys.stdout, sys.stderr
        t0 = time.monotonic()
        self.started_here = not ray.is_initialized()
        if self.started_here:
            kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
            if address:
                failed = None
                with held_stderr() as said:  # Ray's retry warnings: shown only if the join works
                    try:
                        ray.init(address=address, **kw)
                    except (ConnectionError, RuntimeError, ray.exceptions.RayError) as e:
                        failed = e
                if failed is not None:
                    sys.stdout = self._stdout
                    raise join_failed(address, failed, token) from None
                sys.stderr.write(said["text"])
            else:
                ray.init(num_cpus=max(1, int(jobs)), **kw)
        self.startup_s = time.monotonic() - t0
        nodes = [n for n in ray.nodes() if n.get("Alive")]
        self.max_node_cpus = max((n["Resources"].get("CPU", 0) for n in nodes), default=1) or 1
        total = ray.cluster_resources()
        self.gpus = int(total.get("GPU", 0)) if device == "cuda" else 0
        self.memory = float(total.get("memory", 0.0))
        self.cpus = total.get("CPU", 0)
        self.hosts = len(nodes)
        self._remote = ray.remote(_ray_step)
        self._refs: dict[Any, int] = {}
        self._next = 0

    def describe(self) -> str:
        gpus = f", {self.gpus} GPU" if self.gpus else ""
        return f"ray, {self.hosts} node(s), {self.cpus:g} CPU{gpus}"

    def request(self, res: dict[str, Any]) -> dict[str, Any]:
        """Ray options for a step with declared ``res`` (clamped so it can be placed)."""
        opts = {
            "num_cpus": min(max(1, int(res.get("cpus", 1))), self.max_node_cpus),
            "num_gpus": min(int(res.get("gpus", 0)), self.gpus),
            "max_retries": 0,
        }
        mem = float(res.get("memory_gb", 0.0)) * 2**30
        if mem > 0 and self.memory > 0:
            opts["memory"] = int(min(mem, self.memory))
        return opts

    def fits(self, res: dict[str, Any]) -> bool:
        return True  # Ray queues tasks until their resources are free

    def running(self) -> int:
        return len(self._refs)

    def submit(self, task: StepTask) -> int:
        ref = self._remote.options(name=task.label, **self.request(task.resources)).remote(task)
        handle = self._next
        self._next += 1
        self._refs[ref] = handle
        return handle

    def wait(self, timeout: float | None = None) -> list[tuple[int, dict]]:
        if not self._refs:
            return []
        ready, _ = self.ray.wait(list(self._refs), num_returns=1, timeout=timeout)
        if ready:  # take everything else that is done too
            ready, _ = self.ray.wait(list(self._refs), num_returns=len(self._refs), timeout=0)
        out = []
        for ref in ready:
            handle = self._refs.pop(ref)
            try:
                result = self.ray.get(ref)
            except self.ray.exceptions.RayError as e:
                result = {"ok": False, "reason": f"worker lost ({type(e).__name__})", "tail": str(e)[-2000:]}
            out.append((handle, result))
        return out

    def abort(self) -> None:
        for ref in list(self._refs):
            try:
                self.ray.cancel(ref, force=True)
            except Exception:  # already finished or its worker is gone
                pass
        self._refs.clear()

    def close(self) -> None:
        if self._refs:
            self.abort()
        if self.started_here:
            self.ray.shutdown()
        sys.stdout = self._stdout

"""Executors: where the steps of a run (or a batch of runs) execute.

The runner (holoflow/flow/scheduler.py) decides WHAT runs: it resolves cache keys, serves cached steps and
hands every step that must run to an executor as a :class:`StepTask`. An executor decides WHERE and
WHEN, within the resources each stage declares in pipeline.yaml (``resources: {cpus, gpus,
memory_gb}``); it never changes what a step computes. Every step still runs as its own process
(holoflow.flow.executors.step.run_step), which commits its outputs to the shared store itself.

- ``local`` (holoflow.flow.executors.local): up to ``-j N`` CPU slots on this machine, one slot per GPU.
- ``ray`` (holoflow.flow.executors.ray_executor): one Ray task per step, requesting the stage's resources
  from a Ray cluster (a local one, or ``--address`` of an existing cluster).

Interface (both): ``fits(resources)``, ``submit(task) -> handle``, ``wait(timeout) -> [(handle,
result)]``, ``abort()``, ``close()``, plus ``kind``, ``default_retries`` and ``describe()``; the local
one also ``expect(needs, ahead)`` (warm templates and compiled numba kernels for the steps to come).
"""

from __future__ import annotations

# The module step_env loads first: importing a submodule binds its name on the package, which would
# otherwise replace the function step_env below whenever the module is first imported later.
from . import step_env as _step_env_module  # noqa: F401
from .task import StepTask, gpu_ids, host_memory_gb, step_env

__all__ = ["StepTask", "gpu_ids", "host_memory_gb", "make_executor", "step_env"]


def make_executor(
    kind: str,
    jobs: int = 1,
    address: str | None = None,
    device: str = "cpu",
    on_line=None,
    warm: bool = True,
    connect_timeout: float | None = None,
):
    """The executor named ``kind`` (local | ray). ``on_line(label, line)`` gets each step's output lines
    (local only; called on the thread that calls ``wait``); ``warm`` false: every local step exec'd;
    ``connect_timeout``: seconds Ray waits for the cluster at ``address`` (None: 60)."""
    if kind == "local":
        from .local import LocalExecutor

        return LocalExecutor(jobs, device=device, on_line=on_line, warm=warm)
    if kind == "ray":
        from .ray_connect import CONNECT_TIMEOUT_S
        from .ray_executor import RayExecutor

        return RayExecutor(
            address=address,
            jobs=jobs,
            device=device,
            connect_timeout=CONNECT_TIMEOUT_S if connect_timeout is None else connect_timeout,
        )
    from ..pipeline import PipelineError

    raise PipelineError(f"--executor {kind!r}: unknown executor; fix: use local or ray")

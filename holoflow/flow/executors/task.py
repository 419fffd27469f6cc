"""What an executor is handed and how a step's process is set up, the same on every executor: the
:class:`StepTask`, the step's thread-count environment, and this host's GPUs and memory."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from holoflow.stage import THREAD_VARS


@dataclass
class StepTask:
    """Everything a worker needs to run and commit one step (plain data: it is pickled for Ray)."""

    store: str  # store root, absolute; the same path on every worker
    stage: str
    label: str  # display name ("detail", or "s2/detail" in a batch)
    key: str
    components: dict[str, Any]
    spec: dict[str, Any]  # the job spec, less output_dir/work_dir (made by the worker)
    program: str  # absolute path; a .py runs with the worker's own python
    cwd: str
    resources: dict[str, Any]  # the stage's declared {cpus, gpus, memory_gb}
    provenance: dict[str, Any]  # facts known before the step runs (engine, params, inputs ...)
    replace: bool = False  # --force: install the new record even if one exists
    attempt: int = 1
    env: dict[str, str] = field(default_factory=dict)
    modules: list[str] = field(default_factory=list)  # modules outside the project it imports


def step_env(resources: dict[str, Any]) -> dict[str, str]:
    """Thread-count variables for a step: its declared cpus, capped at this host's cores; and idle
    OpenMP threads (torch's, numba's: one libgomp) spin for GOMP_SPINCOUNT = 30000 polls (tens of
    microseconds) before they sleep, unless the environment sets GOMP_SPINCOUNT or OMP_WAIT_POLICY.
    libgomp's default spins 10x longer, which starves a step's own main thread on a loaded machine;
    sleeping at once (PASSIVE) makes every kernel launch wait for a futex wake-up (figures:
    docs/bench-preview.md).

    BLAS code paths are pinned (``holoflow.flow.executors.step_env.PINNED_ENV``) so that Intel and AMD hosts run
    the same kernels. The same on every executor, so a step computes the same bytes under ``-j 1``,
    ``-j N`` and Ray.
    """
    from .step_env import PINNED_ENV

    n = str(max(1, min(int(resources.get("cpus", 1)), os.cpu_count() or 1)))
    env = {v: n for v in THREAD_VARS}
    env.update({k: os.environ.get(k, v) for k, v in PINNED_ENV.items()})  # CPU-independent BLAS paths
    if "OMP_WAIT_POLICY" in os.environ:
        env["OMP_WAIT_POLICY"] = os.environ["OMP_WAIT_POLICY"]
    else:
        env["GOMP_SPINCOUNT"] = os.environ.get("GOMP_SPINCOUNT", "30000")
    return env


def gpu_ids() -> list[str]:
    """GPUs this process may use: $CUDA_VISIBLE_DEVICES if set, else /dev/nvidiaN (no torch import)."""
    vis = os.environ.get("CUDA_VISIBLE_DEVICES")
    if vis is not None:
        return [g.strip() for g in vis.split(",") if g.strip() and g.strip() != "-1"]
    try:
        return sorted((n[6:] for n in os.listdir("/dev") if n.startswith("nvidia") and n[6:].isdigit()), key=int)
    except OSError:
        return []


def host_memory_gb() -> float:
    """Total memory of this host, GiB (from /proc/meminfo; 0 when unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) / 2**20
    except OSError:
        pass
    return 0.0

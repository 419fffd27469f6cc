"""Compile ahead: a run compiles the numba kernels of its steps to come while the steps before them run.

Every ``@njit(cache=True)`` kernel compiles on its first call after an install and keeps its machine
code in numba's disk cache; on a fresh install the preview's first run spends ~13 s of pre_opt
compiling the splatting kernels, ~1.5 s of point_cloud and ~0.1 s of inp_set (2-core CPU). Numba
looks in its disk cache whenever a kernel meets a new signature, so a process that compiles the
kernels before the step that calls them hands them over through that cache.

A local run whose steps to come import a file of :data:`KERNELS` starts one such process beside its
first step (``python -m holoflow.flow.executors.ahead MODULE...``): it calls each module's
``compile_ahead()`` (the kernels on tiny inputs of the dtypes the stages pass), in the order the
steps need them. The preview's steps before pre_opt use one core each, so on a 2-core machine the
compiling takes the idle one. A step that starts before its kernels are in the cache compiles the
missing ones itself, as without this process. With a warm cache the process only loads the kernels.
It runs at nice 19, on what the steps leave idle: on a busy machine (no idle core) it would only take
the steps' time, for nothing when the cache is warm (~2.4 s of CPU then: imports, loading the kernels).
"""
from __future__ import annotations

import importlib
import os
import subprocess
import sys

#: project file whose importers call numba kernels -> module whose ``compile_ahead()`` compiles them
KERNELS = {
    "holoflow/geometry/zbuffer_cpu.py": "holoflow.geometry.zbuffer_cpu",
    "holoflow/geometry/layers.py": "holoflow.geometry.layers",
    "holoflow/splat/cpu.py": "holoflow.splat.rasterize",
    "holoflow/recon/inpaint.py": "holoflow.recon.inpaint",
}


def modules_for(closures: list[list[str]]) -> list[str]:
    """The :data:`KERNELS` modules of the steps to come, each once, in the order of the first step
    that imports it (``closures``: each step's project files, relative to the root, in run order)."""
    out: list[str] = []
    for files in closures:
        for f, module in KERNELS.items():
            if f in files and module not in out:
                out.append(module)
    return out


def start(modules: list[str], cwd: str) -> subprocess.Popen | None:
    """The compiling process for ``modules`` (None when there are none); it dies with the thread that
    starts it (the run's scheduling thread)."""
    if not modules:
        return None
    from .step import popen

    return popen([sys.executable, "-m", __name__, *modules], cwd=cwd, stdin=subprocess.DEVNULL,
                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def main(modules: list[str]) -> int:
    os.nice(19)
    for name in modules:
        importlib.import_module(name).compile_ahead()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

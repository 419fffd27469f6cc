"""Compile ahead: a run compiles the numba kernels of its steps to come while the steps before them run.

Every ``@njit(cache=True)`` kernel compiles on its first call after an install and keeps its machine
code in numba's disk cache, so a fresh install's first run compiles pre_opt's splatting kernels,
point_cloud's and inp_set's inside those steps (seconds: docs/bench-preview.md). Numba
looks in its disk cache whenever a kernel meets a new signature, so a process that compiles the
kernels before the step that calls them hands them over through that cache.

A project module takes part by defining a top-level ``compile_ahead()`` that calls its kernels on
tiny inputs of the dtypes the stages pass. A local run whose steps to come import such modules
starts one process beside its first step (``python -m holoflow.flow.executors.ahead ROOT:MODULE...``)
that calls them in the order the steps need them. The preview's steps before pre_opt use one core
each, so on a 2-core machine the compiling takes the idle one. A step that starts before its kernels
are in the cache compiles the missing ones itself, as without this process. With a warm cache the
process only imports the modules and loads the kernels. It runs at nice 19, on what the
steps leave idle: on a busy machine it would only take the steps' time.
"""

from __future__ import annotations

import importlib
import os
import re
import sys

HOOK = re.compile(r"^def compile_ahead\(", re.M)


def modules_for(closures: list[dict[str, str]]) -> list[str]:
    """``ROOT:MODULE`` of the project modules that define ``compile_ahead``, each once, in the order of
    the first step that imports it (``closures``: each step's {file: search root}, in run order)."""
    out: list[str] = []
    seen: set[str] = set()
    for files in closures:
        for f, root in files.items():
            if f in seen:
                continue
            seen.add(f)
            if _has_hook(f):
                name = os.path.relpath(f, root)[:-3].replace(os.sep, ".").removesuffix(".__init__")
                out.append(f"{root}:{name}")
    return out


def _has_hook(file: str) -> bool:
    try:
        with open(file, encoding="utf-8") as fh:
            return HOOK.search(fh.read()) is not None
    except (OSError, UnicodeDecodeError):
        return False


def start(modules: list[str], cwd: str):
    """The compiling process (``subprocess.Popen``) for ``modules``, None when there are none; it dies
    with the thread that starts it (the run's scheduling thread)."""
    if not modules:
        return None
    import subprocess

    from .step import popen

    return popen(
        [sys.executable, "-m", __name__, *modules],
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def main(modules: list[str]) -> int:
    os.nice(19)
    for item in modules:
        root, _, name = item.rpartition(":")
        if root not in sys.path:
            sys.path.append(root)
        importlib.import_module(name).compile_ahead()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

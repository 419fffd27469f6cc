"""The machine a measurement ran on, in one line, and the load around it (the benches and eval name both).

Every table names the machine it was measured on (:func:`machine`) and the load average around the
measurement (:func:`load`): the development machines are shared 2-core CPUs.
"""

from __future__ import annotations

import os
import platform


def cpu_model() -> str:
    """The CPU's marketing name from /proc/cpuinfo (else ``platform.processor()``)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine() -> str:
    """One line naming this machine: architecture, usable cores, CPU model, OS."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{platform.machine()}, {cores} cores (nproc), {cpu_model()}, {platform.system()}"


def load() -> str:
    """The 1 / 5 / 15 min load averages, e.g. ``"0.7/0.5/0.4"``."""
    return "/".join(f"{x:.1f}" for x in os.getloadavg())

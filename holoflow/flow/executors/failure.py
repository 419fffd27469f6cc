"""Why a step or its commit failed, in words a user can act on (docs/faults.md).

Two kinds: the store's file system refused a write (full, over quota, read-only), which no retry of
the step can fix and which leaves every committed step intact; and a step process that died (a signal,
or an exit after running out of memory).
"""

from __future__ import annotations

import errno

#: errno -> what it means for the store, and the fix
STORE_ERRNOS = {
    errno.ENOSPC: (
        "the store's disk is full",
        "free space on it (`holoflow gc --yes` drops old runs) or pass --store on another disk",
    ),
    errno.EDQUOT: (
        "the store's disk quota is used up",
        "free space (`holoflow gc --yes` drops old runs) or raise the quota",
    ),
    errno.EROFS: (
        "the store's file system is read-only",
        "remount it read-write or pass --store DIR on a writable disk",
    ),
}

#: what a failed step's log may say -> the words added to its reason
LOG_MARKS = (
    (
        (
            "MemoryError",
            "std::bad_alloc",
            "Cannot allocate memory",
            "out of memory",
            "failed to map segment from shared object",
        ),
        "out of memory (its log says so: lower the stage's sizes or give it more memory)",
    ),
    (
        ("can't start new thread",),  # a thread's stack could not be mapped, or a thread limit hit
        "out of memory or of threads (its log says a thread could not start: give it more memory, or "
        "raise the process's thread limit)",
    ),
    (("No space left on device", "Disk quota exceeded"), "a disk is full (its log says so)"),
    (("Read-only file system",), "a file system is read-only (its log says so)"),
)


def store_problem(e: BaseException) -> str | None:
    """One line for an OSError that says the store cannot take writes (full, quota, read-only);
    None for any other error (a bug or a damaged file: let it surface as it is)."""
    if not isinstance(e, OSError) or e.errno not in STORE_ERRNOS:
        return None
    what, fix = STORE_ERRNOS[e.errno]
    where = f" (writing {e.filename})" if e.filename else ""
    return f"{what}{where}; every step committed before it is kept; fix: {fix}, then run again"


def exit_reason(code: int, log_tail: str = "") -> str:
    """``killed by signal N`` or ``exit code N``, plus what the log tail says went wrong when it is the
    machine's fault: out of memory (a MemoryError under a memory rlimit, a failed C++ or CUDA
    allocation), a full disk, a read-only file system."""
    if code < 0:
        return f"killed by signal {-code}"
    reason = f"exit code {code}"
    for marks, words in LOG_MARKS:
        if any(m in log_tail for m in marks):
            return f"{reason}, {words}"
    return reason

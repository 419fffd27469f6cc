"""The CPU a step ran on, as its record keeps it, and the step environment that pins the numeric
libraries' CPU-dependent code paths (docs/store.md, "Bytes and CPU kinds").

A CPU kind is its vendor and its ISA class: the x86-64 micro-architecture level (psABI v1-v4) plus the
few extensions the libraries here dispatch on beyond it. Two CPUs of one kind take the same code
paths in torch, NumPy, OpenBLAS, MKL and OpenCV; across kinds some steps' bytes may differ in the last
bits. The kind goes in the record (provenance), not in the cache key: a key per CPU kind would make
every step of a mixed cluster or a borrowed machine recompute work whose result is valid either way,
and early cutoff already compares the bytes that come out.
"""

from __future__ import annotations

import functools
import platform

#: x86-64 micro-architecture levels (System V psABI): the /proc/cpuinfo flags each adds
LEVELS = (
    ("x86-64-v2", ("cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3")),
    ("x86-64-v3", ("avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave")),
    ("x86-64-v4", ("avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl")),
)
#: extensions past v4 that a library here dispatches on (NumPy's AVX512_SPR, oneDNN's AMX / VNNI / BF16)
EXTRAS = ("avx512_fp16", "avx512_bf16", "avx512_vnni", "amx_tile")

#: environment for every step (unless the user's environment sets the variable): MKL (torch's BLAS) on
#: its AVX2 branch (conditional numerical reproducibility), OpenBLAS (NumPy's and SciPy's) on its Haswell
#: kernels: both what they pick by themselves on an AMD EPYC, and what an Intel Xeon would otherwise
#: leave for AVX-512 kernels; and NumPy's own SIMD loops on their AVX2 (x86-64-v3) versions: its
#: AVX-512 ones (SVML) round exp / log / pow differently. The libraries' other dispatch (torch's ATen,
#: oneDNN, OpenCV, numba) is left alone: it does not change a run's bytes. What it costs and what it
#: changed: docs/store.md.
PINNED_ENV = {
    "MKL_CBWR": "AVX2",
    "OPENBLAS_CORETYPE": "Haswell",
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
}


def isa_class(flags: set[str], machine: str | None = None) -> str:
    """'x86-64-v4+avx512_bf16+...' from a CPU's flags; the machine name (e.g. 'aarch64') off x86."""
    machine = machine or platform.machine()
    if machine not in ("x86_64", "AMD64"):
        return machine
    level = "x86-64-v1"
    for name, need in LEVELS:
        if not all(f in flags for f in need):
            break
        level = name
    return "+".join([level, *(e for e in EXTRAS if e in flags)])


@functools.lru_cache(maxsize=1)
def cpu_facts() -> dict[str, str]:
    """{vendor, model, isa} of this host's CPU (from /proc/cpuinfo; empty strings where unknown)."""
    info: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if not line.strip():
                    break  # the first processor is enough
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    flags = set(info.get("flags", "").split())
    return {"vendor": info.get("vendor_id", ""), "model": info.get("model name", ""), "isa": isa_class(flags)}


def cpu_kind(facts: dict | None) -> str:
    """'AuthenticAMD x86-64-v4' from a record's cpu facts; '' when the record has none (older records)."""
    return f"{facts.get('vendor', '')} {facts.get('isa', '')}".strip() if facts else ""


def bytes_note(kinds: dict[str, list[str]]) -> str:
    """One line for `holoflow status`: which CPU kinds made the steps' bytes ({kind: [stage]}; '' = a record
    from before kinds were recorded), against this machine's."""
    here = cpu_kind(cpu_facts())
    known = {k: v for k, v in kinds.items() if k}
    if not known:
        return ""
    if list(known) == [here]:
        where = f"every recorded step ran on this machine's CPU kind ({here})"
    else:
        where = (
            "steps ran on "
            + "; ".join(f"{k} ({', '.join(v)})" for k, v in sorted(known.items()))
            + f"; this machine: {here}"
        )
    return (
        f"bytes: {where}; another CPU kind may give other bytes in some steps' last bits, so a rerun "
        f"there can miss early cutoff (docs/store.md, Bytes and CPU kinds)"
    )

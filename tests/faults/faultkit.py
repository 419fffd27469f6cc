"""Helpers of the fault and load tests: copy a reference store into one whose last step (export) is
still to compute, run `holoflow` as a process, find a step's process, compare a run's final bytes."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROMPT = "a small wooden cabin"
#: the stage the fault tests make run again: the last one (0.3 s), so each test recomputes only it
TAIL = "export"


def holoflow(
    store: Path, *args: str, timeout: float = 600, env: dict | None = None, prompt: str | None = PROMPT
) -> subprocess.CompletedProcess:
    """`holoflow COMMAND [PROMPT] --profile tiny --store STORE ...` as a process (text output)."""
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        *args[:1],
        *([prompt] if args[:1] == ("run",) and prompt else []),
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--store",
        str(store),
        *args[1:],
    ]
    if args[:1] in (("run",), ("status",)):
        cmd += ["--profile", "tiny"]
    return subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout, env={**os.environ, **(env or {})}
    )


def popen(store: Path, *args: str, env: dict | None = None, prompt: str = PROMPT, **kw) -> subprocess.Popen:
    """`holoflow run PROMPT --profile tiny --store STORE ARGS...` started as a process; ``args`` that
    start with a command other than run (``"gc", "--yes"``) start that command instead."""
    head = ["run", prompt] if not args or args[0].startswith("-") else [args[0]]
    args = args if not args or args[0].startswith("-") else args[1:]
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        *head,
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--store",
        str(store),
        *(["--profile", "tiny"] if head[0] == "run" else []),
        *args,
    ]
    return subprocess.Popen(
        cmd,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
        **kw,
    )


def run_json(store: Path, *args: str, **kw) -> dict:
    done = holoflow(store, "run", "--json", *args, **kw)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def final_bytes(summary: dict) -> dict[str, dict[str, str]]:
    """stage -> {output file: digest} of a run summary (--json) or a run.json."""
    return {
        n: {k: (v["digest"] if isinstance(v, dict) else v) for k, v in s["outputs"].items()}
        for n, s in summary["stages"].items()
    }


def without_tail(ref: Path, dest: Path, drop: tuple[str, ...] = (TAIL,)) -> Path:
    """Copy store ``ref`` to ``dest`` less the runs and the records + objects of the ``drop`` stages:
    a store where every step but those is cached (as if the run had stopped before them)."""
    shutil.copytree(ref, dest, symlinks=True)
    for p in ("runs", "pins", "tmp"):
        shutil.rmtree(dest / p)
        (dest / p).mkdir()
    (dest / "latest").unlink()
    drop_digests, keep_digests = set(), set()
    for kp in (dest / "keys").glob("*.json"):
        rec = json.loads(kp.read_text())
        digests = {e["digest"] for e in rec["outputs"].values()} | {rec["provenance"]["log"]}
        if rec["stage"] in drop:
            drop_digests |= digests
            kp.unlink()
            (dest / "stages" / f"{rec['stage']}.json").unlink(missing_ok=True)
        else:
            keep_digests |= digests
    for d in drop_digests - keep_digests:
        (dest / "objects" / d[:2] / d).unlink()
    return dest


def verify_clean(store: Path) -> None:
    done = holoflow(store, "verify")
    assert done.returncode == 0 and "all match their hashes" in done.stdout, done.stdout + done.stderr


def one_clear_line(stderr: str, *words: str) -> str:
    """The error the user sees: no traceback, a `holoflow:` line that names ``words``; returns it."""
    assert "Traceback" not in stderr, stderr[-3000:]
    lines = [ln for ln in stderr.splitlines() if ln.startswith("holoflow:")]
    assert lines, stderr[-3000:]
    hit = [ln for ln in lines if all(w.lower() in ln.lower() for w in words)]
    assert hit, f"no line naming {words}: {lines}"
    print("user sees:", hit[0])
    return hit[0]


def descendants(pid: int) -> list[tuple[int, str]]:
    """(pid, comm or argv) of every process below ``pid`` (from /proc; Linux)."""
    kids: dict[int, list[int]] = {}
    names: dict[int, str] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            p = int(stat.parent.name)
            kids.setdefault(int(fields[1]), []).append(p)
            names[p] = (
                (stat.parent / "comm").read_text().strip()
                + " "
                + (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            )
        except (OSError, IndexError, ValueError):
            pass
    out, todo = [], [pid]
    while todo:
        for c in kids.get(todo.pop(), []):
            out.append((c, names.get(c, "")))
            todo.append(c)
    return out


def wait_for_step(proc: subprocess.Popen, stage: str, timeout: float = 120.0) -> int:
    """The pid of ``stage``'s process under ``proc`` (exec'd, or forked warm and named after its
    program), once it runs."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid, name in descendants(proc.pid):
            if name.startswith(f"{stage}.py"[:15] + " ") or f"stages/{stage}.py" in name:
                return pid
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.01)
    raise AssertionError(f"{stage} never started")

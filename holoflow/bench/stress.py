"""`holoflow bench stress`: the same run again and again beside CPU hogs, failing on any digest difference.

Each round runs ``holoflow run PROMPT --profile PROFILE`` into two fresh stores (or, with ``--force
STAGE``, reruns those steps in one store that already holds the run) while ``--hogs`` busy-loop
processes compete for the cores, and compares every artifact's digest with the first round's. It
stops after ``--rounds`` rounds or once ``--budget-s`` seconds have passed (after the round that
crosses it). The hogs are started and stopped by their own pids. Writes docs/bench-stress.md.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator

from holoflow.evaluation.machine import load, machine

PROMPT = "a small wooden cabin"
HOG = "while True: pass"


@contextlib.contextmanager
def hogs(n: int) -> Iterator[list[int]]:
    """``n`` busy-loop processes (one core each) for the duration; yields their pids."""
    procs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(n)]
    try:
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            p.kill()
            p.wait()


def run_digests(store: Path, pipeline: Path, prompt: str, profile: str, *extra: str) -> dict[str, dict[str, str]]:
    """``holoflow run`` into ``store``; {stage: {file: digest}} of the run (raises on failure)."""
    cmd = [
        sys.executable,
        "-m",
        "holoflow",
        "run",
        prompt,
        "--pipeline",
        str(pipeline),
        "--profile",
        profile,
        "--store",
        str(store),
        "--json",
        *extra,
    ]
    done = subprocess.run(cmd, cwd=pipeline.parent, capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        raise RuntimeError(f"holoflow run failed (exit {done.returncode}): {done.stderr.strip()[-2000:]}")
    return {name: dict(s["outputs"]) for name, s in json.loads(done.stdout)["stages"].items()}


def differences(ref: dict[str, dict[str, str]], got: dict[str, dict[str, str]]) -> list[str]:
    """'stage/file' of every artifact whose digest differs (or is missing on one side)."""
    out = []
    for stage in sorted(set(ref) | set(got)):
        a, b = ref.get(stage, {}), got.get(stage, {})
        out += [f"{stage}/{f}" for f in sorted(set(a) | set(b)) if a.get(f) != b.get(f)]
    return out


def stress(
    pipeline: Path,
    rounds: int,
    n_hogs: int,
    budget_s: float,
    profile: str = "tiny",
    prompt: str = PROMPT,
    force: list[str] | None = None,
    store: Path | None = None,
) -> dict:
    """Rounds of runs beside ``n_hogs`` hogs. Without ``force``: each round two fresh stores; with it,
    ``--force`` of those stages in ``store`` (which must already hold the run). Returns {rounds: [{seconds,
    diffs}], reference, load}; any non-empty diffs is a reproducibility failure."""
    t0 = time.monotonic()
    result = {"rounds": [], "load_before": load(), "hogs": n_hogs, "force": force or []}
    with tempfile.TemporaryDirectory(prefix="holoflow-stress-") as tmp, hogs(n_hogs):
        extra = [a for s in force or [] for a in ("--force", s)]
        ref = run_digests(store, pipeline, prompt, profile) if force else None
        for i in range(rounds):
            t = time.monotonic()
            if force:
                runs = [run_digests(store, pipeline, prompt, profile, *extra)]
            else:
                runs = [run_digests(Path(tmp) / f"r{i}{ab}", pipeline, prompt, profile) for ab in "ab"]
                ref = ref or runs[0]
            diffs = sorted({d for r in runs for d in differences(ref, r)})
            result["rounds"].append({"seconds": round(time.monotonic() - t, 1), "diffs": diffs})
            if time.monotonic() - t0 > budget_s:
                break
    result["load_after"] = load()
    result["reference"] = ref
    return result


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench stress", description=__doc__.splitlines()[0])
    ap.add_argument("--pipeline", default="pipeline.yaml")
    ap.add_argument("--profile", default="tiny")
    ap.add_argument("--prompt", default=PROMPT)
    ap.add_argument("--rounds", type=int, default=5, help="rounds, two fresh stores each (default 5)")
    ap.add_argument("--hogs", type=int, default=4, help="busy-loop processes beside the runs (default 4)")
    ap.add_argument("--budget-s", type=float, default=1800.0, help="stop after the round that passes this")
    ap.add_argument(
        "--force",
        action="append",
        default=[],
        metavar="STAGE",
        help="rerun STAGE in one store instead of two fresh stores a round (repeatable)",
    )
    ap.add_argument("--store", help="the store for --force (default: a fresh one, run once first)")
    ap.add_argument("--out", default="docs/bench-stress.md")
    args = ap.parse_args(argv)
    pipe = Path(args.pipeline).absolute()
    with tempfile.TemporaryDirectory(prefix="holoflow-stress-store-") as tmp:
        store = Path(args.store or tmp) / ("" if args.store else "s")
        res = stress(pipe, args.rounds, args.hogs, args.budget_s, args.profile, args.prompt, args.force, store)
    text = report(args, res)
    Path(args.out).write_text(text)
    print(text)
    return 1 if any(r["diffs"] for r in res["rounds"]) else 0


def report(args, res: dict) -> str:
    bad = [r for r in res["rounds"] if r["diffs"]]
    what = f"`--force {' --force '.join(res['force'])}` in one store" if res["force"] else "two fresh stores a round"
    lines = [
        "# Stress: the same run, bytes compared, beside CPU hogs (`holoflow bench stress`)",
        "",
        f"Machine: {machine()}. Load average before / after: {res['load_before']} / {res['load_after']}.",
        "",
        f"`holoflow bench stress --profile {args.profile} --rounds {args.rounds} --hogs {args.hogs}"
        + "".join(f" --force {s}" for s in res["force"])
        + f"`: {len(res['rounds'])} rounds, {what}, "
        f"{res['hogs']} busy-loop processes beside them, every artifact's digest compared with the first run's.",
        "",
        "| round | seconds | differing artifacts |",
        "|---|---|---|",
    ]
    for i, r in enumerate(res["rounds"]):
        lines.append(f"| {i + 1} | {r['seconds']} | {', '.join(r['diffs']) or 'none'} |")
    n = sum(len(v) for v in (res["reference"] or {}).values())
    lines += [
        "",
        f"Result: {'FAILED: ' + str(len(bad)) + ' round(s) differ' if bad else 'all rounds byte-identical'} "
        f"({n} artifacts a run).",
        "",
    ]
    return "\n".join(lines)

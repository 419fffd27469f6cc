"""`holoflow bench startup`: what a step pays before its first line of work, cold (exec'd) against
warm (forked from a template), and the preview end to end both ways, optionally against another
checkout of holoflow (``--baseline DIR``, e.g. a worktree of an older commit) in the same run.

Per step: a probe program that imports what the stage program's import closure imports (the heavy
third-party modules and the project's own) is launched the way the local executor launches a step:
exec'd, or forked from a template that preloaded the heavy ones (the template's own start is not
counted: once per run). End to end: ``holoflow run PROMPT`` on a fresh store, per round one run of
each variant (baseline, cold, warm) back to back, so the machine's load hits all of them alike;
medians over the rounds, and the runs' output digests compared. Writes docs/bench-startup.md.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from holoflow.evaluation.machine import load, machine

PROMPT = "a cozy wooden cabin at night"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="holoflow bench startup", description=__doc__.splitlines()[0])
    ap.add_argument("--pipeline", default="pipeline.yaml")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    ap.add_argument("--prompt", default=PROMPT)
    ap.add_argument("--baseline", metavar="DIR", help="another holoflow checkout run with its own pipeline.yaml")
    ap.add_argument("--no-e2e", action="store_true", help="per-step start-up only")
    ap.add_argument("--out", default="docs/bench-startup.md")
    args = ap.parse_args(argv)
    pipe = Path(args.pipeline).absolute()
    steps = step_startup(pipe, args.rounds)
    e2e = None if args.no_e2e else end_to_end(pipe, args.prompt, args.rounds, args.baseline)
    text = report(args, steps, e2e)
    Path(args.out).write_text(text)
    print(text)
    return 0


def step_startup(pipe_path: Path, rounds: int) -> list[tuple[str, list[float], list[float]]]:
    """Per stage: (name, cold seconds per round, warm seconds per round) of its import probe."""
    from holoflow.flow.cachekey import CodeHasher
    from holoflow.flow.executors.step import ExecStep
    from holoflow.flow.executors.task import step_env
    from holoflow.flow.executors.warm import Launcher, preload
    from holoflow.flow.pipeline import load as load_pipeline

    pipe = load_pipeline(pipe_path)
    hasher = CodeHasher(pipe.root, None)
    rows = []
    launcher = Launcher()
    try:
        with tempfile.TemporaryDirectory(prefix="holoflow-startup-") as tmp:
            probes, union = [], {}
            for name, stage in pipe.stages.items():
                program = pipe.program(name)
                heavy = preload(sorted(hasher.external(program)))
                ours = sorted(
                    _module_name(f) for f in hasher.closure(program) if f.startswith("holoflow/") and f.endswith(".py")
                )
                probe = Path(tmp) / f"{name}.py"
                probe.write_text("".join(f"import {m}\n" for m in heavy + ours))
                threads = step_env(stage.resources.as_dict())
                union.setdefault(tuple(threads.items()), set()).update(heavy)
                probes.append((name, probe, threads))
            (Path(tmp) / "nothing.py").write_text("")
            for threads, heavy in union.items():  # as the executor's expect(): one template each,
                launcher.ensure(dict(threads), sorted(heavy))  # its imports done before timing
                _timed(
                    lambda: launcher.start(
                        str(Path(tmp) / "nothing.py"), "-", str(pipe.root), dict(os.environ, **dict(threads))
                    )
                )
            for name, probe, threads in probes:
                env = dict(os.environ, PYTHONUNBUFFERED="1", **threads)
                cold, warm = [], []
                for _ in range(rounds):
                    cold.append(_timed(lambda: ExecStep([sys.executable, str(probe), "-"], str(pipe.root), env)))
                    warm.append(_timed(lambda: launcher.start(str(probe), "-", str(pipe.root), env)))
                rows.append((name, cold, warm))
    finally:
        launcher.close()
    return rows


def _module_name(rel: str) -> str:
    mod = rel[:-3].replace("/", ".")
    return mod[:-9] if mod.endswith(".__init__") else mod


def _timed(start) -> float:
    t0 = time.perf_counter()
    proc = start()
    out = proc.stdout.read()
    proc.stdout.close()
    status, _ = proc.wait4()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"start-up probe failed: {out.decode(errors='replace')[-500:]}")
    return time.perf_counter() - t0


def end_to_end(pipe: Path, prompt: str, rounds: int, baseline: str | None) -> dict:
    """{variant: [(seconds, output digests), ...]} over ``rounds`` interleaved rounds."""
    variants = ([("baseline", Path(baseline).absolute(), [])] if baseline else []) + [
        ("cold", pipe.parent, ["--cold"]),
        ("warm", pipe.parent, []),
    ]
    out: dict = {v[0]: [] for v in variants}
    with tempfile.TemporaryDirectory(prefix="holoflow-e2e-") as tmp:
        for r in range(rounds):
            for name, root, extra in variants:
                store = Path(tmp) / f"{name}-{r}"
                env = dict(os.environ, PYTHONPATH=str(root))
                env.pop("HOLOFLOW_COLD", None)
                cmd = [
                    sys.executable,
                    "-m",
                    "holoflow",
                    "run",
                    prompt,
                    "--pipeline",
                    str(root / "pipeline.yaml"),
                    "--store",
                    str(store),
                    "--json",
                    *extra,
                ]
                t0 = time.perf_counter()
                p = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
                dt = time.perf_counter() - t0
                if p.returncode != 0:
                    raise RuntimeError(f"{name} run failed: {p.stderr[-800:]}")
                summary = json.loads(p.stdout)
                digests = {n: s["outputs"] for n, s in summary["stages"].items()}
                out[name].append((dt, digests))
                print(f"round {r + 1}/{rounds} {name}: {dt:.1f} s (load {load()})", file=sys.stderr)
    return out


def report(args, steps, e2e) -> str:
    med = statistics.median
    lines = [
        "# Start-up: cold against warm steps",
        "",
        f"`holoflow bench startup --rounds {args.rounds}`"
        + (f" `--baseline {args.baseline}`" if args.baseline else "")
        + f", {time.strftime('%Y-%m-%d')}, "
        f"on {machine()}; load average after: {load()} (1 is the bench itself; more means other work "
        f"shared the machine). All timings are wall clock, medians of interleaved rounds.",
        "",
        "## Per step: launch + imports, until the step could start working",
        "",
        "Probe: a program importing what the stage's import closure imports; cold = exec'd "
        "(`python PROBE`), warm = forked from the run's template (which preloaded the heavy "
        "third-party modules once).",
        "",
        "| stage | cold s | warm s | saved s |",
        "|---|---:|---:|---:|",
    ]
    for name, cold, warm in steps:
        lines.append(f"| {name} | {med(cold):.2f} | {med(warm):.3f} | {med(cold) - med(warm):.2f} |")
    total = sum(med(c) - med(w) for _, c, w in steps)
    lines += ["", f"Sum of the savings over the {len(steps)} steps: {total:.1f} s.", ""]
    if e2e:
        lines += [
            "## The preview end to end (fresh store)",
            "",
            f'`holoflow run "{args.prompt}"` (default profile), each round runs every variant back to back.',
            "",
            "| variant | seconds per round | median s | vs first |",
            "|---|---|---:|---:|",
        ]
        first = med([t for t, _ in next(iter(e2e.values()))])
        for name, runs in e2e.items():
            secs = [t for t, _ in runs]
            lines.append(
                f"| {name} | {', '.join(f'{s:.1f}' for s in secs)} | {med(secs):.1f} | {med(secs) / first:.2f}x |"
            )
        ref = e2e["cold"][0][1]
        same = all(d == ref for name in ("cold", "warm") for _, d in e2e[name])
        lines += [
            "",
            f"Output digests of every stage, cold and warm, all rounds: {'identical' if same else 'DIFFERENT'}.",
        ]
        if "baseline" in e2e:
            base = e2e["baseline"][0][1]
            differ = sorted(n for n in ref if base.get(n) != ref[n])
            lines.append(
                f"Against the baseline checkout: {', '.join(differ) or 'none'} differ (code changed between the two)."
            )
        lines.append("")
    return "\n".join(lines)

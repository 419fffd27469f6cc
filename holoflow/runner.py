"""The runner: plan a run over the DAG, serve cached steps, run the rest as processes, commit results.

A step runs as ``[python, PROGRAM, JOB.json]`` (or ``[PROGRAM, JOB.json]``) with no shell, its outputs
in a staging folder under the store's tmp/. After exit 0 each output is hashed and moved into
objects/, then the key record is written last (docs/store.md). Nothing here imports numpy or torch:
a fully cached run and ``status`` cost a few stats and JSON reads.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import __version__
from .cachekey import CodeHasher, cache_key, components, reasons, tree_digest
from .pipeline import Pipeline, PipelineError, Resolved, check_files, resolve
from .store import Store, remove_tree

LOG_TAIL = 15


class StepFailed(Exception):
    """A step exited non-zero (its log is kept); earlier committed steps stay committed."""


class Interrupted(KeyboardInterrupt):
    """SIGTERM: stop like Ctrl-C (kill the running step, keep committed steps)."""


@dataclass
class Options:
    prompt: str | None = None
    profile: str | None = None
    sets: list[str] = field(default_factory=list)
    uses: list[str] = field(default_factory=list)
    from_stage: str | None = None
    until: str | None = None
    only: str | None = None
    force: list[str] = field(default_factory=list)
    dry_run: bool = False
    seed: int | None = None
    device: str | None = None
    lock_timeout: float | None = None
    verbose: bool = False


@dataclass
class Context:
    """Everything a run or a status check needs, resolved once."""

    pipe: Pipeline
    store: Store
    resolved: dict[str, Resolved]
    seed: int
    prompt: str | None
    profile: str | None
    uses: dict[str, Path]
    hasher: CodeHasher
    device: str
    verbose: bool = False

    @classmethod
    def build(cls, pipe: Pipeline, store: Store, opts: Options) -> "Context":
        resolved = resolve(pipe, opts.profile, opts.sets)
        uses = parse_uses(pipe, opts.uses)
        prompt = opts.prompt
        if prompt is None:
            info = store.run_info(store.latest_run_id())
            prompt = info.get("prompt") if info else None
        seed = pipe.seed if opts.seed is None else opts.seed
        device = opts.device or os.environ.get("HOLOFLOW_DEVICE", "cpu")
        if device == "auto":
            device = "cuda" if cuda_present() else "cpu"
        if device not in ("cpu", "cuda"):
            raise PipelineError(f"device {device!r} (from --device or HOLOFLOW_DEVICE); fix: use cpu, cuda "
                                f"or auto")
        hasher = CodeHasher(pipe.root, store.root / "cache" / "code.json")
        return cls(pipe, store, resolved, seed, prompt, opts.profile or pipe.default_profile, uses,
                   hasher, device, opts.verbose)

    def components(self, name: str, outputs: dict[str, dict]) -> dict[str, Any]:
        """Key components of stage ``name`` given its upstream stages' outputs."""
        s = self.pipe.stages[name]
        r = self.resolved[name]
        paths = [self.pipe.program(name)] + [self.pipe.path_of(c) for c in s.code]
        code = self.hasher.version(paths)
        inputs = {inp: {"stage": up, "tree": tree_digest(outputs[up])} for inp, up in s.inputs.items()}
        prompt = None
        if s.prompt:
            if self.prompt is None:
                raise PipelineError(f"stage '{name}' needs a prompt and no earlier run gave one; fix: "
                                    f"holoflow run \"a small wooden cabin\"")
            prompt = self.prompt
        return components(name, code, r.engine, r.params, inputs, self.seed, prompt)


def cuda_present() -> bool:
    """An NVIDIA driver is loaded (checked without importing torch; the step itself still decides)."""
    return os.path.exists("/proc/driver/nvidia/version") or os.path.exists("/dev/nvidia0")


def parse_uses(pipe: Pipeline, uses: list[str]) -> dict[str, Path]:
    out = {}
    for item in uses:
        if "=" not in item:
            raise PipelineError(f"--use {item!r}: expected STAGE=PATH; fix: e.g. --use base_pano=my_pano.exr")
        stage, path = item.split("=", 1)
        if stage not in pipe.stages:
            raise PipelineError(f"--use {item!r}: unknown stage '{stage}'; fix: use one of: "
                                f"{', '.join(pipe.stages)}")
        p = Path(path).expanduser().absolute()
        if not p.exists():
            raise PipelineError(f"--use {stage}={path}: no such file or folder; fix: check the path")
        out[stage] = p
    return out


def import_use(ctx: Context, stage: str, src: Path) -> dict[str, dict]:
    """Validate the user's file(s) for ``stage`` and hash them into the store; returns the output map."""
    s = ctx.pipe.stages[stage]
    if src.is_dir():
        files = {p.relative_to(src).as_posix(): p for p in sorted(src.rglob("*")) if p.is_file()}
        if not files:
            raise PipelineError(f"--use {stage}={src}: the folder is empty; fix: point at the stage's files")
    else:
        name = s.primary or src.name
        if s.primary and Path(s.primary).suffix.lower() != src.suffix.lower():
            raise PipelineError(f"--use {stage}={src}: {stage}'s main output is {s.primary}, got a "
                                f"{src.suffix or 'suffix-less'} file; fix: convert it (e.g. oiiotool IN -o "
                                f"OUT{Path(s.primary).suffix})")
        files = {name: src}
    for rel, p in files.items():
        _validate_file(stage, p)
    outputs = {}
    for rel, p in files.items():
        tmp = ctx.store.staging(f"use-{stage}") / "f"
        shutil.copyfile(p, tmp)
        outputs[rel] = ctx.store.put(tmp)
        tmp.parent.rmdir()
    return outputs


def _validate_file(stage: str, p: Path) -> None:
    ext = p.suffix.lower()
    if ext == ".exr":
        from .io.exr import ExrError, read_exr

        try:
            read_exr(p)
        except ExrError as e:
            raise PipelineError(f"--use {stage}: {p} does not open as EXR ({e}); fix: pass an OpenEXR "
                                f"file (e.g. oiiotool IN -o OUT.exr)") from None
    elif ext == ".ply":
        from plyfile import PlyData

        try:
            with open(p, "rb") as f:
                PlyData.read(f)
        except Exception as e:  # plyfile raises several types for a broken file
            raise PipelineError(f"--use {stage}: {p} does not open as PLY ({type(e).__name__}: {e}); fix: "
                                f"pass a valid PLY file") from None


# -- planning ------------------------------------------------------------------------------------
def select(pipe: Pipeline, opts: Options, uses: dict[str, Path]) -> tuple[set[str], set[str], set[str]]:
    """(selected: may run, needed: must be available, forced) from --from/--until/--only/--force/--use."""
    for flag, name in (("--from", opts.from_stage), ("--until", opts.until), ("--only", opts.only),
                       *(("--force", f) for f in opts.force if f != "all")):
        if name is not None and name not in pipe.stages:
            raise PipelineError(f"{flag} {name}: unknown stage; fix: use one of: {', '.join(pipe.stages)}")
    selected = set(pipe.stages)
    if opts.from_stage:
        selected &= pipe.downstream({opts.from_stage})
    if opts.until:
        selected &= pipe.upstream({opts.until})
    if opts.only:
        selected = {opts.only}
    forced = set(selected) if "all" in opts.force else set(opts.force)
    if forced - selected:
        raise PipelineError(f"--force {', '.join(sorted(forced - selected))}: not among the stages this run "
                            f"covers ({', '.join(s for s in pipe.stages if s in selected)}); fix: widen "
                            f"--from/--until/--only")
    needed: set[str] = set()
    stack = list(selected)
    while stack:
        n = stack.pop()
        if n in needed:
            continue
        needed.add(n)
        if n not in uses:
            stack.extend(pipe.stages[n].inputs.values())
    return selected, needed, forced


# -- running -------------------------------------------------------------------------------------
def run(ctx: Context, opts: Options, display, lock_message=print) -> dict[str, Any]:
    """Run the pipeline; returns the summary (also what --json prints). Raises StepFailed on failure."""
    pipe, store = ctx.pipe, ctx.store
    selected, needed, forced = select(pipe, opts, ctx.uses)
    order = [n for n in pipe.stages if n in needed]
    for n in order:
        if n not in ctx.uses and n in selected:
            check_files(pipe, n)
    if opts.dry_run:
        return dry_run(ctx, order, selected, forced)
    store.ensure()
    store.lock(opts.lock_timeout, "run", lock_message)
    try:
        old_handler = signal.signal(signal.SIGTERM, _raise_interrupted)
    except ValueError:          # not the main thread: leave signals to the caller
        old_handler = None
    summary: dict[str, Any] = {"pipeline": str(pipe.path), "store": str(store.root), "prompt": ctx.prompt,
                               "profile": ctx.profile, "seed": ctx.seed, "stages": {}, "ok": False}
    latest = store.run_info(store.latest_run_id()) or {}
    for name, st in latest.get("stages", {}).items():
        if st.get("how") == "used" and name in needed and name not in ctx.uses:
            display.line(f"note: the latest run took {name} from {st.get('source')} (--use); this run "
                         f"does not: pass --use {name}=... again to keep it")
    run_id: str | None = None
    outputs: dict[str, dict] = {}
    ran: set[str] = set()
    t_run = time.monotonic()
    try:
        display.start_run(len(order))
        for i, name in enumerate(order, 1):
            t0 = time.monotonic()
            entry: dict[str, Any] = {}
            if name in ctx.uses:
                outputs[name] = import_use(ctx, name, ctx.uses[name])
                entry = {"how": "used", "source": str(ctx.uses[name]), "key": None}
                ran.add(name)             # downstream of an import is not an early cutoff
                display.end_step(name, i, len(order), "used", 0.0, f" ({ctx.uses[name]})")
            else:
                comp = ctx.components(name, outputs)
                key = cache_key(comp)
                rec = store.record(key)
                ok = rec is not None and store.outputs_ok(rec)
                if ok and name not in forced:
                    upstream_ran = any(u in ran for u in pipe.upstream({name}) - {name})
                    how = "cut off" if upstream_ran else "cached"
                    display.end_step(name, i, len(order), how, 0.0)
                elif name not in selected:
                    why = "; ".join(explain(ctx, name, comp))
                    raise PipelineError(f"stage '{name}' is needed but has no cached result ({why}); fix: "
                                        f"run it too (drop --from/--only, or widen --until)")
                else:
                    if run_id is None:
                        run_id = store.new_run_id()
                        for done in outputs:
                            store.link_outputs(run_id, done, outputs[done])
                        _write_run(ctx, summary, outputs, run_id)
                    display.start_step(name, i, len(order))
                    rec = execute(ctx, name, comp, key, run_id, outputs, display)
                    ran.add(name)
                    how = "ran"
                    display.end_step(name, i, len(order), how, time.monotonic() - t0,
                                     _rss_note(rec))
                outputs[name] = rec["outputs"]
                entry = {"how": how, "key": key}
            entry["seconds"] = round(time.monotonic() - t0, 3)
            entry["outputs"] = {k: v["digest"] for k, v in outputs[name].items()}
            summary["stages"][name] = entry
            if run_id is not None:
                store.link_outputs(run_id, name, outputs[name])
                _write_run(ctx, summary, outputs, run_id)      # a killed run keeps what it finished
        summary["ok"] = True
    finally:
        if old_handler is not None:
            signal.signal(signal.SIGTERM, old_handler)
        summary["seconds"] = round(time.monotonic() - t_run, 3)
        try:
            ctx.hasher.save()
            _finish_run(ctx, summary, outputs, run_id)
        finally:
            store.unlock()
    return summary


def _finish_run(ctx: Context, summary: dict, outputs: dict[str, dict], run_id: str | None) -> None:
    """Write the final run.json and move `latest`, unless nothing changed since the latest run."""
    store = ctx.store
    if run_id is None:
        if not summary["stages"]:
            return
        latest = store.run_info(store.latest_run_id())
        same = latest is not None and latest.get("prompt") == ctx.prompt and {
            n: (s.get("key"), {k: v["digest"] for k, v in s.get("outputs", {}).items()})
            for n, s in latest.get("stages", {}).items()} == {
            n: (e.get("key"), e["outputs"]) for n, e in summary["stages"].items()}
        if same or not summary["ok"]:
            summary["run"] = store.latest_run_id() if same else None
            return
        run_id = store.new_run_id()
        for n in summary["stages"]:
            store.link_outputs(run_id, n, outputs[n])
    _write_run(ctx, summary, outputs, run_id)
    summary["run"] = run_id


def _write_run(ctx: Context, summary: dict, outputs: dict[str, dict], run_id: str) -> None:
    stages = {n: {"key": e.get("key"), "how": e["how"], "outputs": outputs[n],
                  **({"source": e["source"]} if "source" in e else {})}
              for n, e in summary["stages"].items()}
    info = {"run": run_id, "pipeline": str(ctx.pipe.path), "prompt": ctx.prompt, "profile": ctx.profile,
            "seed": ctx.seed, "ok": summary["ok"], "seconds": summary.get("seconds"), "stages": stages,
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    ctx.store.write_run(run_id, info, latest=True)


def _raise_interrupted(signum, frame):
    raise Interrupted(f"holoflow run stopped by signal {signum}")


def _rss_note(rec: dict) -> str:
    rss = rec.get("provenance", {}).get("peak_rss_mb")
    return f", peak {rss:.0f} MB" if rss else ""


def execute(ctx: Context, name: str, comp: dict, key: str, run_id: str, outputs: dict[str, dict],
            display) -> dict:
    """Run one step as a process; on exit 0 commit its outputs and key record; returns the record."""
    store, pipe = ctx.store, ctx.pipe
    stage, r = pipe.stages[name], ctx.resolved[name]
    staging = store.staging(name)
    out_dir, work_dir = staging / "out", staging / "work"
    out_dir.mkdir()
    work_dir.mkdir()
    spec = {"stage": name, "engine": r.engine, "params": r.params, "seed": ctx.seed,
            "prompt": ctx.prompt or "", "device": ctx.device,
            "inputs": {inp: str(store.run_dir(run_id) / up) for inp, up in stage.inputs.items()},
            "output_dir": str(out_dir), "work_dir": str(work_dir), "key": key, "run": run_id}
    job = staging / "job.json"
    job.write_text(json.dumps(spec, indent=1, sort_keys=True))
    program = pipe.program(name)
    argv = [sys.executable, str(program), str(job)] if program.suffix == ".py" else [str(program), str(job)]
    env = dict(os.environ, PYTHONUNBUFFERED="1", HOLOFLOW_STAGE=name)
    log_path = staging / "log.txt"
    meta: dict[str, Any] = {}
    started = time.time()
    t0 = time.monotonic()
    import subprocess

    with open(log_path, "wb") as log:
        proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, cwd=pipe.root, env=env, preexec_fn=_die_with_parent)
        try:
            for raw in proc.stdout:
                log.write(raw)
                line = raw.decode(errors="replace").rstrip("\n")
                if line.startswith("@progress "):
                    p = _json_or_none(line[10:])
                    if p and "done" in p and "total" in p:
                        display.step_progress(name, int(p["done"]), int(p["total"]), str(p.get("what", "")))
                elif line.startswith("@meta "):
                    m = _json_or_none(line[6:])
                    if isinstance(m, dict):
                        meta.update(m)
                elif ctx.verbose:
                    display.line(f"    {name}| {line}")
            _, status, usage = os.wait4(proc.pid, 0)
            proc.returncode = code = os.waitstatus_to_exitcode(status)
        except BaseException:
            proc.kill()
            proc.wait()
            remove_tree(staging)
            raise
    wall = time.monotonic() - t0
    if code != 0:
        kept = _keep_failed_log(store, run_id, name, log_path)
        remove_tree(staging)
        reason = f"killed by signal {-code}" if code < 0 else f"exit code {code}"
        tail = _tail(kept, LOG_TAIL)
        raise StepFailed(f"stage '{name}' failed ({reason}); nothing from it was committed; earlier steps "
                         f"are kept.\n--- last lines of {kept} ---\n{tail}")
    files = sorted(p for p in out_dir.rglob("*") if not p.is_dir())
    bad = [p for p in files if p.is_symlink() or not p.is_file()]
    if bad or not files:
        kept = _keep_failed_log(store, run_id, name, log_path)
        remove_tree(staging)
        what = f"wrote a non-regular file {bad[0].relative_to(out_dir)}" if bad else "wrote no output files"
        raise StepFailed(f"stage '{name}' {what}; fix the stage program (log: {kept})")
    committed = {p.relative_to(out_dir).as_posix(): store.put(p) for p in files}
    log_entry = store.put(log_path)
    import platform

    versions = {"python": platform.python_version(), "holoflow": __version__, "platform": platform.platform()}
    versions.update(meta.pop("versions", {}) if isinstance(meta.get("versions"), dict) else {})
    if "torch" in meta:
        versions["torch"] = meta["torch"]
    rec = {
        "key": key, "stage": name, "components": comp, "outputs": committed,
        "provenance": {
            "run": run_id, "engine": r.engine, "params": r.params, "seed": ctx.seed, "device": ctx.device,
            "inputs": {inp: {"stage": up, "outputs": {k: v["digest"] for k, v in outputs[up].items()}}
                       for inp, up in stage.inputs.items()},
            "program": stage.run, "argv0": Path(argv[0]).name, "meta": meta, "versions": versions,
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
            "wall_s": round(wall, 3), "cpu_s": round(usage.ru_utime + usage.ru_stime, 3),
            "peak_rss_mb": round(usage.ru_maxrss / 1024, 1), "exit_code": code,
            "log": log_entry["digest"], "log_size": log_entry["size"],
        },
    }
    store.write_record(rec)
    remove_tree(staging)
    return rec


def _die_with_parent() -> None:
    """In the child: die if the runner dies (a SIGKILLed runner leaves no orphan step behind)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)    # PR_SET_PDEATHSIG
    except OSError:
        pass


def _keep_failed_log(store: Store, run_id: str, name: str, log_path: Path) -> Path:
    dest = store.root / "logs" / f"{run_id}-{name}.log"
    dest.parent.mkdir(exist_ok=True)
    shutil.copyfile(log_path, dest)
    return dest


def _tail(path: Path, n: int) -> str:
    lines = [ln for ln in path.read_text(errors="replace").splitlines() if not ln.startswith("@progress ")]
    return "\n".join(lines[-n:]) if lines else "(the step printed nothing)"


def _json_or_none(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return None


# -- dry run and status --------------------------------------------------------------------------
def dry_run(ctx: Context, order: list[str], selected: set[str], forced: set[str]) -> dict[str, Any]:
    """What a run would do, without locking or running anything."""
    plan = status(ctx, order)
    stages = {}
    for name in order:
        st = plan[name]
        if name in ctx.uses:
            how = "use"
        elif name in forced or st["state"] != "fresh":
            how = "run" if name in selected else "missing (not selected)"
        else:
            how = "cached"
        stages[name] = {"how": how, "state": st["state"], "reasons": st["reasons"]}
    return {"dry_run": True, "stages": stages, "ok": True}


def status(ctx: Context, order: list[str] | None = None) -> dict[str, dict[str, Any]]:
    """Per stage: state fresh | stale | missing, the reasons, and the key when it can be known."""
    store = ctx.store
    order = order or list(ctx.pipe.stages)
    outputs: dict[str, dict] = {}
    out: dict[str, dict[str, Any]] = {}
    for name in order:
        s = ctx.pipe.stages[name]
        if name in ctx.uses:
            out[name] = {"state": "fresh", "reasons": [f"used: {ctx.uses[name]}"], "key": None}
            outputs[name] = _digests_of(ctx.uses[name], s.primary)
            continue
        if s.prompt and ctx.prompt is None:
            out[name] = {"state": "missing", "key": None,
                         "reasons": ["no prompt yet (holoflow status \"PROMPT\", or run once)"]}
            continue
        bad_up = [u for u in s.inputs.values() if u not in outputs]
        if bad_up:
            comp = ctx.components(name, {u: outputs.get(u, {}) for u in s.inputs.values()})
            own = [r for r in explain(ctx, name, comp) if not r.startswith("input changed")]
            own = [r for r in own if r not in ("never run", "key changed")]
            ups = sorted(set(bad_up), key=list(ctx.pipe.stages).index)
            never = store.last_key(name) is None
            out[name] = {"state": "missing" if never else "stale", "key": None,
                         "reasons": (["never run"] if never else own)
                         + [f"upstream not fresh: {', '.join(ups)}"]}
            continue
        comp = ctx.components(name, outputs)
        key = cache_key(comp)
        rec = store.record(key)
        if rec is not None:
            missing = [rel for rel, e in rec["outputs"].items() if not store.check(e)]
            if not missing:
                out[name] = {"state": "fresh", "reasons": [], "key": key}
                outputs[name] = rec["outputs"]
                continue
            out[name] = {"state": "missing", "key": key,
                         "reasons": [f"output missing or corrupted: {', '.join(missing[:3])}"]}
            continue
        why = explain(ctx, name, comp)
        out[name] = {"state": "missing" if why == ["never run"] else "stale", "reasons": why,
                     "key": key}
    ctx.hasher.save()
    return out


def explain(ctx: Context, name: str, comp: dict) -> list[str]:
    last = ctx.store.last_key(name)
    rec = ctx.store.record(last) if last else None
    if rec is None:
        return ["never run"]
    return reasons(rec["components"], comp)


def _digests_of(path: Path, primary: str | None) -> dict[str, dict]:
    from .store import sha256_file

    if path.is_dir():
        return {p.relative_to(path).as_posix(): {"digest": sha256_file(p)} for p in sorted(path.rglob("*"))
                if p.is_file()}
    return {primary or path.name: {"digest": sha256_file(path)}}


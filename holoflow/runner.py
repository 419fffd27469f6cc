"""The runner: plan a run (or a batch of scenes) over the DAG, serve cached steps, hand the rest to an
executor, record the runs. What is fresh or stale and why: holoflow/status.py.

A step runs as ``[python, PROGRAM, JOB.json]`` (or ``[PROGRAM, JOB.json]``) with no shell, its outputs
in a staging folder under the store's tmp/; after exit 0 its outputs are hashed into objects/ and the
key record is written last (holoflow/executors/step.py, docs/store.md). Executors (local threads with
resource slots, or Ray) only decide where and when a step runs (docs/scale.md). Nothing here imports
numpy, torch or subprocess: a fully cached run and ``status`` cost a few stats and JSON reads.
"""
from __future__ import annotations

import json
import os
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .cachekey import CodeHasher, cache_key, components, tree_digest
from .executors import StepTask
from .pipeline import Pipeline, PipelineError, Resolved, check_files, profile_device, resolve
from .status import chosen_engine, dry_run, engine_note, explain
from .uses import dropped_uses, import_use, parse_uses
from .store import Store


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
    jobs: int = 1                   # -j: CPU slots of the local executor (local Ray: its CPUs)
    executor: str = "local"         # local | ray
    address: str | None = None      # Ray cluster address (ray executor)
    retries: int | None = None      # extra attempts per failed step (None: the executor's default)
    models: str | None = None       # --models DIR: every real engine loads from DIR's manifest.json
    cold: bool = False              # --cold: exec every local step (no warm template)


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
    imports: dict[str, dict] = field(default_factory=dict)  # stage -> facts of an image --use (provenance)

    @classmethod
    def build(cls, pipe: Pipeline, store: Store, opts: Options, hasher: CodeHasher | None = None) -> "Context":
        resolved = resolve(pipe, opts.profile, opts.sets)
        device = run_device(pipe, opts)
        resolve_device_engines(resolved, device)
        if opts.models:
            from .models import apply_manifest

            apply_manifest(resolved, Path(opts.models))
        uses = parse_uses(pipe, opts.uses)
        prompt = opts.prompt
        if prompt is None:
            info = store.run_info(store.latest_run_id())
            prompt = info.get("prompt") if info else None
        seed = pipe.seed if opts.seed is None else opts.seed
        hasher = hasher or CodeHasher(pipe.root, store.root / "cache" / "code.json")
        return cls(pipe, store, resolved, seed, prompt, opts.profile or pipe.default_profile, uses,
                   hasher, device, opts.verbose)

    def components(self, name: str, outputs: dict[str, dict]) -> dict[str, Any]:
        """Key components of stage ``name`` given its upstream stages' outputs."""
        s = self.pipe.stages[name]
        r = self.resolved[name]
        code = {**self.hasher.closure(self.pipe.program(name)),
                **self.hasher.version([self.pipe.path_of(c) for c in s.code])}
        inputs = {inp: {"stage": up, "tree": tree_digest(outputs[up])} for inp, up in s.inputs.items()}
        prompt = None
        if s.prompt:
            if self.prompt is None:
                raise PipelineError(f"stage '{name}' needs a prompt and no earlier run gave one; fix: "
                                    f"holoflow run \"a small wooden cabin\"")
            prompt = self.prompt
        return components(name, code, r.engine, r.params, inputs, self.seed, prompt)


def run_device(pipe: Pipeline, opts: Options) -> str:
    """cpu or cuda: ``--device``, else $HOLOFLOW_DEVICE, else what the profile asks for, else cpu
    (auto = cuda when a driver is present). A profile that asks for cuda on a machine without one is
    a PipelineError naming the fix; an explicit cuda is left to the steps (a remote executor may have it)."""
    explicit = opts.device or os.environ.get("HOLOFLOW_DEVICE")
    asked = explicit or profile_device(pipe, opts.profile) or "cpu"
    if asked not in ("cpu", "cuda", "auto"):
        raise PipelineError(f"device {asked!r} (from --device or HOLOFLOW_DEVICE); fix: use cpu, cuda or auto")
    if asked == "auto":
        return "cuda" if cuda_present() else "cpu"
    if asked == "cuda" and not explicit and not cuda_present():
        raise PipelineError(f"profile '{opts.profile}' asks for device cuda and this machine has no CUDA "
                            f"device; fix: run it on a GPU machine, or add --device cpu (slow at full size)")
    return asked


def resolve_device_engines(resolved: dict[str, Resolved], device: str) -> None:
    """A splat stage's engine ``auto`` becomes gsplat on cuda and the CPU rasterizer otherwise, before
    the cache key is made: the key names the rasterizer that really ran."""
    for r in resolved.values():
        if r.engine == "auto" and "gsplat" in r.stage.engines:
            r.engine = "gsplat" if device == "cuda" else "cpu"
            r.overrides["engine"] = f"auto on {device}"


def cuda_present() -> bool:
    """An NVIDIA driver is loaded (checked without importing torch; the step itself still decides)."""
    return os.path.exists("/proc/driver/nvidia/version") or os.path.exists("/dev/nvidia0")


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
@dataclass
class Scene:
    """One scene of a run or batch: its context (prompt, resolved params, seed) and run options."""

    ctx: Context
    opts: Options
    label: str = ""                 # "" for a single run; "s1", "s2", ... in a batch
    sets: list[str] = field(default_factory=list)       # the scene's own --set (for the summary)


class _SceneRun:
    """The state of one scene while the scheduler works through its DAG."""

    def __init__(self, scene: Scene):
        ctx, opts = scene.ctx, scene.opts
        self.scene, self.ctx, self.opts = scene, ctx, opts
        self.selected, self.needed, self.forced = select(ctx.pipe, opts, ctx.uses)
        self.order = [n for n in ctx.pipe.stages if n in self.needed]
        self.pending = list(self.order)           # not yet resolved (cached, used, or committed)
        self.waiting: set[str] = set()            # submitted, or waiting on another scene's same key
        self.outputs: dict[str, dict] = {}
        self.ran: set[str] = set()
        self.run_id: str | None = None
        self.failed: str | None = None
        self.t0: dict[str, float] = {}
        self.summary: dict[str, Any] = {"pipeline": str(ctx.pipe.path), "store": str(ctx.store.root),
                                        "prompt": ctx.prompt, "profile": ctx.profile, "seed": ctx.seed,
                                        "device": ctx.device, "stages": {}, "ok": False}
        if scene.label:
            self.summary.update(label=scene.label, sets=list(scene.sets))

    def name(self, stage: str) -> str:
        return f"{self.scene.label}/{stage}" if self.scene.label else stage


class _Job:
    """One step to compute (one cache key), and every scene stage waiting for it."""

    def __init__(self, task: StepTask, waiters: list[tuple[_SceneRun, str]]):
        self.task = task
        self.waiters = waiters
        self.t0 = time.monotonic()


def run(ctx: Context, opts: Options, display, lock_message=print, executor=None) -> dict[str, Any]:
    """Run the pipeline for one scene; returns the summary (also what --json prints).

    Raises StepFailed when a step fails (after its retries); committed steps stay committed.
    """
    return run_batch([Scene(ctx, opts)], display, lock_message, executor)["scenes"][0]


def run_batch(scenes: list[Scene], display, lock_message=print, executor=None) -> dict[str, Any]:
    """Run several scenes over one store: independent steps run concurrently on ``executor``.

    Steps of all scenes are resolved in topological order; a step whose key is cached is served, one
    whose key another scene is already computing waits for that step (scenes share work where keys
    agree), the rest go to the executor as soon as it has room. A failing step (after ``retries``)
    stops its scene; the other scenes go on. Returns {ok, seconds, scenes: [summary per scene]}.
    """
    first = scenes[0]
    pipe, store, opts = first.ctx.pipe, first.ctx.store, first.opts
    states = [_SceneRun(s) for s in scenes]
    for st in states:
        for n in st.order:
            if n not in st.ctx.uses and n in st.selected:
                check_files(pipe, n)
        check_weights(st)
    if opts.dry_run:
        return {"dry_run": True, "ok": True,
                "scenes": [{**dry_run(st.ctx, st.order, st.selected, st.forced),
                            **({"label": st.scene.label} if st.scene.label else {})} for st in states]}
    store.ensure()
    store.lock(opts.lock_timeout, "run", lock_message)
    try:
        old_handler = signal.signal(signal.SIGTERM, _raise_interrupted)
    except ValueError:          # not the main thread: leave signals to the caller
        old_handler = None
    batch = {"ok": False, "scenes": [st.summary for st in states]}
    t_run = time.monotonic()
    make = (lambda: executor) if executor is not None else (
        lambda: make_executor_for(opts, first.ctx.device, display))
    sched = _Scheduler(states, make, display, opts.retries)
    try:
        sched.warn_dropped_uses()
        sched.loop()
        batch["ok"] = all(st.failed is None for st in states)
    finally:
        if sched.executor_made is not None and sched.executor_made.running():
            sched.executor_made.abort()
        if old_handler is not None:
            signal.signal(signal.SIGTERM, old_handler)
        seconds = round(time.monotonic() - t_run, 3)
        batch["seconds"] = seconds
        if sched.executor_made is not None:
            batch["executor"] = sched.executor_made.describe()
        try:
            if executor is None and sched.executor_made is not None:
                sched.executor_made.close()
            first.ctx.hasher.save()
            for st in states:
                st.summary["seconds"] = seconds
                st.summary["ok"] = st.failed is None and not st.pending
                _finish_run(st, latest=len(states) == 1)
            if len(states) > 1:
                _finish_batch(store, states)
        finally:
            store.unlock()
    failed = [st for st in states if st.failed]
    if failed:
        more = f"\n({len(failed) - 1} more scene(s) failed: {', '.join(s.scene.label for s in failed[1:])})" \
            if len(failed) > 1 else ""
        err = StepFailed(failed[0].failed + more)
        err.batch = batch
        raise err
    return batch


def check_weights(st: "_SceneRun") -> None:
    """Before any step starts: every model the selected real-model engines load is here, or one
    PipelineError line names what is missing and the command that lists how to get it."""
    from .models import ENGINE_MODELS

    ctx = st.ctx
    wanted = {n: ctx.resolved[n] for n in st.order
              if n in st.selected and n not in ctx.uses and ctx.resolved[n].engine in ENGINE_MODELS}
    if not wanted:
        return
    from .models import needs

    missing = [m for m in needs(wanted) if not m.present]
    if missing:
        names = ", ".join(f"{m.stage}.{m.param} ({m.model or m.role})" for m in missing[:3])
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise PipelineError(f"{len(missing)} model(s) not found locally: {names}{more}; fix: "
                            f"`holoflow models list --profile {ctx.profile}` says where each comes from "
                            f"(or `holoflow models random DIR` + --models DIR for random weights)")


def make_executor_for(opts: Options, device: str, display):
    """The executor ``opts`` asks for; output lines of a step reach ``display`` when one step runs."""
    from .executors import make_executor

    def on_line(label: str, line: str) -> None:
        if line.startswith("@progress "):
            p = _json_or_none(line[10:])
            if p and "done" in p and "total" in p and opts.jobs == 1:
                display.step_progress(label, int(p["done"]), int(p["total"]), str(p.get("what", "")))
        elif opts.verbose and not line.startswith("@meta "):
            display.line(f"    {label}| {line}")

    return make_executor(opts.executor, opts.jobs, opts.address, device, on_line=on_line, warm=not opts.cold)


class _Scheduler:
    """Resolve steps as their inputs become known; keep the executor busy; commit results to scenes."""

    def __init__(self, states: list[_SceneRun], make_executor, display, retries: int | None):
        self.states, self.make_executor, self.display, self._retries = states, make_executor, display, retries
        self.executor_made = None                 # made on the first step to run (a cached run needs none)
        self.expected = False                     # the executor was told the steps to come (expect)
        self.total = sum(len(st.order) for st in states)
        self.done = 0
        self.inflight: dict[str, _Job] = {}       # key -> job (queued or running)
        self.queue: list[_Job] = []               # jobs not yet submitted (in resolution order)
        self.running: dict[int, _Job] = {}        # executor handle -> job
        self.forced_done: dict[str, dict] = {}    # forced keys recomputed in this batch -> record

    def warn_dropped_uses(self) -> None:
        for st in self.states:
            for name, source in dropped_uses(st.ctx).items():
                if name in st.needed:
                    self.display.line(f"note: the latest run took {name} from {source} (--use); "
                                      f"this run does not: pass --use {name}=... again to keep it")

    @property
    def executor(self):
        if self.executor_made is None:
            self.executor_made = self.make_executor()
        return self.executor_made

    @property
    def retries(self) -> int:
        return self._retries if self._retries is not None else self.executor.default_retries

    def loop(self) -> None:
        self.display.start_run(self.total)
        while True:
            for st in self.states:
                self.advance(st)
            while self.queue and self.executor.fits(self.queue[0].task.resources):
                self.submit(self.queue.pop(0))
            if not self.running:
                if self.queue:      # nothing runs and the head does not fit: cannot happen (clamped)
                    raise RuntimeError(f"step {self.queue[0].task.label} can never be scheduled")
                return
            for handle, result in self.executor.wait(timeout=0.5):
                self.finish(self.running.pop(handle), result)

    def advance(self, st: _SceneRun) -> None:
        """Resolve every stage of ``st`` whose inputs are known: used, cached, shared, or queued."""
        if st.failed:
            return
        pipe, ctx = st.ctx.pipe, st.ctx
        for name in list(st.pending):
            if name in st.waiting:
                continue
            if name not in ctx.uses and any(u not in st.outputs for u in pipe.stages[name].inputs.values()):
                continue
            st.t0.setdefault(name, time.monotonic())
            if name in ctx.uses:
                st.outputs[name] = import_use(ctx, name, ctx.uses[name])
                st.ran.add(name)             # downstream of an import is not an early cutoff
                info = {"how": "used", "source": str(ctx.uses[name]), "key": None}
                if name in ctx.imports:
                    info["import"] = ctx.imports[name]
                self.resolved(st, name, info, f" ({ctx.uses[name]})")
                continue
            comp = ctx.components(name, st.outputs)
            key = cache_key(comp)
            forced = name in st.forced
            rec = self.forced_done.get(key) if forced else ctx.store.record(key)
            if rec is not None and ctx.store.outputs_ok(rec):
                upstream_ran = any(u in st.ran for u in pipe.upstream({name}) - {name})
                st.outputs[name] = rec["outputs"]
                self.resolved(st, name, {"how": "cut off" if upstream_ran else "cached", "key": key})
                continue
            if name not in st.selected:
                why = "; ".join(explain(ctx, name, comp))
                raise PipelineError(f"stage '{name}' is needed but has no cached result ({why}); fix: "
                                    f"run it too (drop --from/--only, or widen --until)")
            st.waiting.add(name)
            if key in self.inflight:
                self.inflight[key].waiters.append((st, name))
                continue
            job = _Job(self.task(st, name, comp, key, forced), [(st, name)])
            self.inflight[key] = job
            self.queue.append(job)

    def task(self, st: _SceneRun, name: str, comp: dict, key: str, forced: bool) -> StepTask:
        ctx, pipe = st.ctx, st.ctx.pipe
        if st.run_id is None:
            st.run_id = ctx.store.new_run_id()
            for done in st.outputs:
                ctx.store.link_outputs(st.run_id, done, st.outputs[done])
            _write_run(st, latest=len(self.states) == 1)
        stage, r = pipe.stages[name], ctx.resolved[name]
        spec = {"stage": name, "engine": r.engine, "params": r.params, "seed": ctx.seed,
                "prompt": ctx.prompt or "", "device": ctx.device,
                "inputs": {inp: str(ctx.store.run_dir(st.run_id) / up) for inp, up in stage.inputs.items()},
                "key": key, "run": st.run_id, "cpus": r.resources.cpus}
        prov = {"run": st.run_id, "engine": r.engine, "params": r.params, "seed": ctx.seed, "device": ctx.device,
                "inputs": {inp: {"stage": up, "outputs": {k: v["digest"] for k, v in st.outputs[up].items()}}
                           for inp, up in stage.inputs.items()},
                "program": stage.run}
        return StepTask(store=str(ctx.store.root), stage=name, label=st.name(name), key=key, components=comp,
                        spec=spec, program=str(pipe.program(name)), cwd=str(pipe.root),
                        resources=r.resources.as_dict(), provenance=prov, replace=forced,
                        modules=sorted(ctx.hasher.external(pipe.program(name))))

    def submit(self, job: _Job) -> None:
        if not self.expected and self.executor.kind == "local":
            self.expected = True
            self.executor.expect([(st.ctx.resolved[n].resources.as_dict(), sorted(st.ctx.hasher.external(
                st.ctx.pipe.program(n)))) for st in self.states for n in st.pending if n not in st.ctx.uses])
        for st, name in job.waiters:              # "ran in" counts from the start, not the queue
            st.t0[name] = time.monotonic()
        self.display.start_step(job.task.label, self.done + 1, self.total,
                                f" (attempt {job.task.attempt})" if job.task.attempt > 1 else "")
        self.running[self.executor.submit(job.task)] = job

    def finish(self, job: _Job, result: dict) -> None:
        task = job.task
        if not result.get("ok"):
            if result.get("aborted"):
                return
            where = f" on {result['host']}" if result.get("host") and self.executor.kind != "local" else ""
            if task.attempt <= self.retries and not result.get("bad_output"):
                self.display.line(f"{task.label}: attempt {task.attempt} failed ({result['reason']}{where}); "
                                  f"retrying")
                task.attempt += 1
                self.queue.insert(0, job)
                return
            del self.inflight[task.key]
            tries = f" after {task.attempt} attempts" if task.attempt > 1 else ""
            if result.get("bad_output"):
                msg = f"stage '{task.label}' {result['reason']}; fix the stage program (log: {result['log']})"
            else:
                where_log = f"--- last lines of {result['log']} ---" if result.get("log") else "---"
                msg = (f"stage '{task.label}' failed ({result['reason']}{where}{tries}); nothing from it was "
                       f"committed; earlier steps are kept.\n{where_log}\n{result.get('tail', '')}")
            for st, name in job.waiters:
                st.failed = st.failed or msg
                st.waiting.discard(name)
            return
        rec = result["record"]
        del self.inflight[task.key]
        if task.replace:
            self.forced_done[task.key] = rec
        chosen = chosen_engine(rec)
        note = (_rss_note(rec) + (f" on {result['host']}" if self.executor.kind != "local" else "")
                + (f"; {engine_note(chosen)}" if chosen else ""))
        for i, (st, name) in enumerate(job.waiters):
            st.waiting.discard(name)
            st.outputs[name] = rec["outputs"]
            if i == 0:
                st.ran.add(name)
                self.resolved(st, name, {"how": "ran", "key": task.key}, note, ran=True)
            else:
                upstream_ran = any(u in st.ran for u in st.ctx.pipe.upstream({name}) - {name})
                self.resolved(st, name, {"how": "cut off" if upstream_ran else "cached", "key": task.key})

    def resolved(self, st: _SceneRun, name: str, entry: dict, note: str = "", ran: bool = False) -> None:
        """``name`` of ``st`` has its outputs: summary entry, run links, display line."""
        st.pending.remove(name)
        self.done += 1
        seconds = time.monotonic() - st.t0[name]
        self.display.end_step(st.name(name), self.done, self.total, entry["how"], seconds if ran else 0.0, note)
        entry["seconds"] = round(seconds, 3)
        entry["engine"], entry["device"] = _made_with(st.ctx.store, entry.get("key"), st.ctx.resolved[name].engine)
        entry["outputs"] = {k: v["digest"] for k, v in st.outputs[name].items()}
        st.summary["stages"][name] = entry
        if st.run_id is not None:
            st.ctx.store.link_outputs(st.run_id, name, st.outputs[name])
            _write_run(st, latest=len(self.states) == 1)      # a killed run keeps what it finished


def _made_with(store: Store, key: str | None, engine: str) -> tuple[str, str | None]:
    """(engine, device) a step's record says made its outputs: the engine the step chose itself when it
    resolved one (a depth stage's ``auto``), else ``engine``; (``used``, None) for a used file."""
    rec = store.record(key) if key else None
    if rec is None:
        return ("used", None) if key is None else (engine, None)
    chosen = chosen_engine(rec)
    return (chosen["engine"] if chosen else engine), rec["provenance"].get("device")


def _finish_run(st: _SceneRun, latest: bool) -> None:
    """Write the scene's final run.json (and move `latest` if asked), unless nothing changed since the
    latest run."""
    store, summary, ctx = st.ctx.store, st.summary, st.ctx
    if st.run_id is None:
        if not summary["stages"]:
            summary["run"] = None
            return
        last = store.run_info(store.latest_run_id())
        same = last is not None and last.get("prompt") == ctx.prompt and {
            n: (s.get("key"), {k: v["digest"] for k, v in s.get("outputs", {}).items()})
            for n, s in last.get("stages", {}).items()} == {
            n: (e.get("key"), e["outputs"]) for n, e in summary["stages"].items()}
        if same or not summary["ok"]:
            summary["run"] = store.latest_run_id() if same else None
            return
        st.run_id = store.new_run_id()
        for n in summary["stages"]:
            store.link_outputs(st.run_id, n, st.outputs[n])
    _write_run(st, latest=latest)
    summary["run"] = st.run_id


def _finish_batch(store: Store, states: list[_SceneRun]) -> None:
    """A batch's runs are pinned (gc keeps every scene, not only the latest); `latest` -> the last one."""
    runs = [st.summary.get("run") for st in states if st.summary.get("run")]
    for rid in runs:
        store.pin(rid)
    if runs:
        store.write_run(runs[-1], store.run_info(runs[-1]), latest=True)


def _write_run(st: _SceneRun, latest: bool) -> None:
    ctx, summary = st.ctx, st.summary
    stages = {n: {"key": e.get("key"), "how": e["how"], "outputs": st.outputs[n],
                  **({"source": e["source"]} if "source" in e else {})}
              for n, e in summary["stages"].items()}
    info = {"run": st.run_id, "pipeline": str(ctx.pipe.path), "prompt": ctx.prompt, "profile": ctx.profile,
            "seed": ctx.seed, "ok": summary["ok"], "seconds": summary.get("seconds"), "stages": stages,
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    if st.scene.label:
        info.update(label=st.scene.label, sets=list(st.scene.sets))
    ctx.store.write_run(st.run_id, info, latest=latest)


def _raise_interrupted(signum, frame):
    raise Interrupted(f"holoflow run stopped by signal {signum}")


def _rss_note(rec: dict) -> str:
    rss = rec.get("provenance", {}).get("peak_rss_mb")
    return f", peak {rss:.0f} MB" if rss else ""


def _json_or_none(text: str):
    try:
        return json.loads(text)
    except ValueError:
        return None

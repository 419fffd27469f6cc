"""The scheduler: plan a run (or a batch of scenes) over the DAG, serve cached steps, hand the rest to
an executor, commit results to each scene. The run's inputs: holoflow/flow/context.py; its run.json
records: holoflow/flow/records.py; what is fresh or stale and why: holoflow/flow/status.py.

A step runs as ``[python, PROGRAM, JOB.json]`` (or ``[PROGRAM, JOB.json]``) with no shell, its outputs
in a staging folder under the store's tmp/; after exit 0 its outputs are hashed into objects/ and the
key record is written last (holoflow/flow/executors/step.py, docs/store.md). Executors (local threads with
resource slots, or Ray) only decide where and when a step runs (docs/scale.md). Nothing here imports
numpy, torch or subprocess: a fully cached run and ``status`` cost a few stats and JSON reads.
"""

from __future__ import annotations

import json
import signal
import time
from typing import Any

from .cachekey import cache_key
from .context import BatchItem, Context, Options
from .executors import StepTask, ahead
from .executors.failure import store_problem
from .pipeline import PipelineError, check_files
from .records import SceneRun, finish_batch, finish_run, made_with, write_run
from .status import chosen_engine, dry_run, engine_note, explain
from .uses import dropped_uses, import_note, import_use


class StepFailed(Exception):
    """A step exited non-zero (its log is kept); earlier committed steps stay committed."""


class Interrupted(KeyboardInterrupt):
    """SIGTERM or SIGHUP: stop like Ctrl-C (kill the running step, keep committed steps)."""


class _Job:
    """One step to compute (one cache key), and every scene stage waiting for it."""

    def __init__(self, task: StepTask, waiters: list[tuple[SceneRun, str]]):
        self.task = task
        self.waiters = waiters
        self.t0 = time.monotonic()


def run(ctx: Context, opts: Options, display, lock_message=print, executor=None) -> dict[str, Any]:
    """Run the pipeline for one scene; returns the summary (also what --json prints).

    Raises StepFailed when a step fails (after its retries); committed steps stay committed.
    """
    return run_batch([BatchItem(ctx, opts)], display, lock_message, executor)["scenes"][0]


def run_batch(scenes: list[BatchItem], display, lock_message=print, executor=None) -> dict[str, Any]:
    """Run several scenes over one store: independent steps run concurrently on ``executor``.

    Steps of all scenes are resolved in topological order; a step whose key is cached is served, one
    whose key another scene is already computing waits for that step (scenes share work where keys
    agree), the rest go to the executor as soon as it has room. A failing step (after ``retries``)
    stops its scene; the other scenes go on. Returns {ok, seconds, scenes: [summary per scene]}.
    """
    first = scenes[0]
    pipe, store, opts = first.ctx.pipe, first.ctx.store, first.opts
    states = [SceneRun(s) for s in scenes]
    for st in states:
        for n in st.order:
            if n not in st.ctx.uses and n in st.selected:
                check_files(pipe, n)
    if opts.dry_run:
        return {
            "dry_run": True,
            "ok": True,
            "scenes": [
                {
                    **dry_run(st.ctx, st.order, st.selected, st.forced),
                    **({"label": st.scene.label} if st.scene.label else {}),
                }
                for st in states
            ],
        }
    store.ensure()
    store.lock(opts.lock_timeout, "run", lock_message)
    try:  # SIGTERM and SIGHUP (a closed terminal or ssh) stop it like Ctrl-C
        old_handler = {sig: signal.signal(sig, _raise_interrupted) for sig in (signal.SIGTERM, signal.SIGHUP)}
    except ValueError:  # not the main thread: leave signals to the caller
        old_handler = None
    batch = {"ok": False, "scenes": [st.summary for st in states]}
    t_run = time.monotonic()
    make = (lambda: executor) if executor is not None else (lambda: make_executor_for(opts, first.ctx.device, display))
    sched = _Scheduler(states, make, display, opts.retries)
    try:
        sched.warn_dropped_uses()
        sched.loop()
        batch["ok"] = all(st.failed is None for st in states)
    finally:
        if sched.executor_made is not None and sched.executor_made.running():
            sched.executor_made.abort()
        for sig, handler in (old_handler or {}).items():
            signal.signal(sig, handler)
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
                finish_run(st, latest=len(states) == 1)
            if len(states) > 1:
                finish_batch(store, states)
        except OSError as e:  # a full / read-only store: the step's own error already says so
            if store_problem(e) is None or not any(st.failed for st in states):
                raise
        finally:
            store.unlock()
    failed = [st for st in states if st.failed]
    if failed:
        more = (
            f"\n({len(failed) - 1} more scene(s) failed: {', '.join(s.scene.label for s in failed[1:])})"
            if len(failed) > 1
            else ""
        )
        err = StepFailed(failed[0].failed + more)
        err.batch = batch
        raise err
    return batch


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

    return make_executor(
        opts.executor,
        opts.jobs,
        opts.address,
        device,
        on_line=on_line,
        warm=not opts.cold,
        connect_timeout=opts.connect_timeout,
    )


class _Scheduler:
    """Resolve steps as their inputs become known; keep the executor busy; commit results to scenes."""

    def __init__(self, states: list[SceneRun], make_executor, display, retries: int | None):
        self.states, self.make_executor, self.display, self._retries = states, make_executor, display, retries
        self.executor_made = None  # made on the first step to run (a cached run needs none)
        self.expected = False  # the executor was told the steps to come (expect)
        self.total = sum(len(st.order) for st in states)
        self.done = 0
        self.inflight: dict[str, _Job] = {}  # key -> job (queued or running)
        self.queue: list[_Job] = []  # jobs not yet submitted (in resolution order)
        self.running: dict[int, _Job] = {}  # executor handle -> job
        self.forced_done: dict[str, dict] = {}  # forced keys recomputed in this batch -> record

    def warn_dropped_uses(self) -> None:
        for st in self.states:
            for name, source in dropped_uses(st.ctx).items():
                if name in st.needed:
                    self.display.line(
                        f"note: the latest run took {name} from {source} (--use); "
                        f"this run does not: pass --use {name}=... again to keep it"
                    )

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
                if self.queue:  # nothing runs and the head does not fit: cannot happen (clamped)
                    raise RuntimeError(f"step {self.queue[0].task.label} can never be scheduled")
                return
            for handle, result in self.executor.wait(timeout=0.5):
                self.finish(self.running.pop(handle), result)

    def advance(self, st: SceneRun) -> None:
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
                st.ran.add(name)  # downstream of an import is not an early cutoff
                info = {"how": "used", "source": str(ctx.uses[name]), "key": None}
                if name in ctx.imports:
                    info["import"] = ctx.imports[name]
                self.resolved(st, name, info, f" ({ctx.uses[name]}{import_note(ctx.imports.get(name))})")
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
                raise PipelineError(
                    f"stage '{name}' is needed but has no cached result ({why}); fix: "
                    f"run it too (drop --from/--only, or widen --until)"
                )
            st.waiting.add(name)
            if key in self.inflight:
                self.inflight[key].waiters.append((st, name))
                continue
            job = _Job(self.task(st, name, comp, key, forced), [(st, name)])
            self.inflight[key] = job
            self.queue.append(job)

    def task(self, st: SceneRun, name: str, comp: dict, key: str, forced: bool) -> StepTask:
        ctx, pipe = st.ctx, st.ctx.pipe
        if st.run_id is None:
            st.run_id = ctx.store.new_run_id()
            for done in st.outputs:
                ctx.store.link_outputs(st.run_id, done, st.outputs[done])
            write_run(st, latest=len(self.states) == 1)
        stage, r = pipe.stages[name], ctx.resolved[name]
        spec = {
            "stage": name,
            "engine": r.engine,
            "params": r.params,
            "seed": ctx.seed,
            "prompt": ctx.prompt or "",
            "device": ctx.device,
            "inputs": {inp: str(ctx.store.run_dir(st.run_id) / up) for inp, up in stage.inputs.items()},
            "key": key,
            "run": st.run_id,
            "cpus": r.resources.cpus,
        }
        prov = {
            "run": st.run_id,
            "engine": r.engine,
            "params": r.params,
            "seed": ctx.seed,
            "device": ctx.device,
            "inputs": {
                inp: {"stage": up, "outputs": {k: v["digest"] for k, v in st.outputs[up].items()}}
                for inp, up in stage.inputs.items()
            },
            "program": stage.run,
        }
        return StepTask(
            store=str(ctx.store.root),
            stage=name,
            label=st.name(name),
            key=key,
            components=comp,
            spec=spec,
            program=str(pipe.program(name)),
            cwd=str(pipe.root),
            resources=r.resources.as_dict(),
            provenance=prov,
            replace=forced,
            modules=sorted(ctx.hasher.external(pipe.program(name))),
        )

    def submit(self, job: _Job) -> None:
        if not self.expected and self.executor.kind == "local":
            self.expected = True
            to_come = [(st, n) for st in self.states for n in st.pending if n not in st.ctx.uses]
            self.executor.expect(
                [
                    (st.ctx.resolved[n].resources.as_dict(), sorted(st.ctx.hasher.external(st.ctx.pipe.program(n))))
                    for st, n in to_come
                ],
                ahead.modules_for([st.ctx.hasher.files(st.ctx.pipe.program(n)) for st, n in to_come]),
            )
        for st, name in job.waiters:  # "ran in" counts from the start, not the queue
            st.t0[name] = time.monotonic()
        self.display.start_step(
            job.task.label, self.done + 1, self.total, f" (attempt {job.task.attempt})" if job.task.attempt > 1 else ""
        )
        self.running[self.executor.submit(job.task)] = job

    def finish(self, job: _Job, result: dict) -> None:
        task = job.task
        if not result.get("ok"):
            if result.get("aborted"):
                return
            where = f" on {result['host']}" if result.get("host") and self.executor.kind != "local" else ""
            if task.attempt <= self.retries and not result.get("bad_output") and not result.get("store_error"):
                self.display.line(f"{task.label}: attempt {task.attempt} failed ({result['reason']}{where}); retrying")
                task.attempt += 1
                self.queue.insert(0, job)
                return
            del self.inflight[task.key]
            tries = f" after {task.attempt} attempts" if task.attempt > 1 else ""
            if result.get("bad_output"):
                msg = f"stage '{task.label}' {result['reason']}; fix the stage program (log: {result['log']})"
            elif result.get("store_error"):
                msg = f"stage '{task.label}' was not committed: {result['reason']}"
            else:
                where_log = f"--- last lines of {result['log']} ---" if result.get("log") else "---"
                msg = (
                    f"stage '{task.label}' failed ({result['reason']}{where}{tries}); nothing from it was "
                    f"committed; earlier steps are kept.\n{where_log}\n{result.get('tail', '')}"
                )
            for st, name in job.waiters:
                st.failed = st.failed or msg
                st.waiting.discard(name)
            return
        rec = result["record"]
        del self.inflight[task.key]
        if task.replace:
            self.forced_done[task.key] = rec
        chosen = chosen_engine(rec)
        note = (
            _rss_note(rec)
            + (f" on {result['host']}" if self.executor.kind != "local" else "")
            + (f"; {engine_note(chosen)}" if chosen else "")
        )
        for i, (st, name) in enumerate(job.waiters):
            st.waiting.discard(name)
            st.outputs[name] = rec["outputs"]
            if i == 0:
                st.ran.add(name)
                self.resolved(st, name, {"how": "ran", "key": task.key}, note, ran=True)
            else:
                upstream_ran = any(u in st.ran for u in st.ctx.pipe.upstream({name}) - {name})
                self.resolved(st, name, {"how": "cut off" if upstream_ran else "cached", "key": task.key})

    def resolved(self, st: SceneRun, name: str, entry: dict, note: str = "", ran: bool = False) -> None:
        """``name`` of ``st`` has its outputs: summary entry, run links, display line."""
        st.pending.remove(name)
        self.done += 1
        seconds = time.monotonic() - st.t0[name]
        self.display.end_step(st.name(name), self.done, self.total, entry["how"], seconds if ran else 0.0, note)
        entry["seconds"] = round(seconds, 3)
        entry["engine"], entry["device"] = made_with(st.ctx.store, entry.get("key"), st.ctx.resolved[name].engine)
        entry["outputs"] = {k: v["digest"] for k, v in st.outputs[name].items()}
        st.summary["stages"][name] = entry
        if st.run_id is not None:
            st.ctx.store.link_outputs(st.run_id, name, st.outputs[name])
            write_run(st, latest=len(self.states) == 1)  # a killed run keeps what it finished


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

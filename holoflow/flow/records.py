"""Run records: one scene's state while the scheduler works through its DAG (:class:`SceneRun`), its
``runs/<id>/run.json`` (written as steps finish, so a killed run keeps what it finished), the
no-new-run rule for a fully cached rerun, and a batch's pins (docs/store.md)."""

from __future__ import annotations

import time
from typing import Any

from .context import BatchItem, select
from .status import chosen_engine
from .store import Store


class SceneRun:
    """The state of one scene while the scheduler works through its DAG."""

    def __init__(self, scene: BatchItem):
        ctx, opts = scene.ctx, scene.opts
        self.scene, self.ctx, self.opts = scene, ctx, opts
        self.selected, self.needed, self.forced = select(ctx.pipe, opts, ctx.uses)
        self.order = [n for n in ctx.pipe.stages if n in self.needed]
        self.pending = list(self.order)  # not yet resolved (cached, used, or committed)
        self.waiting: set[str] = set()  # submitted, or waiting on another scene's same key
        self.outputs: dict[str, dict] = {}
        self.ran: set[str] = set()
        self.run_id: str | None = None
        self.failed: str | None = None
        self.t0: dict[str, float] = {}
        self.summary: dict[str, Any] = {
            "pipeline": str(ctx.pipe.path),
            "store": str(ctx.store.root),
            "prompt": ctx.prompt,
            "profile": ctx.profile,
            "seed": ctx.seed,
            "device": ctx.device,
            "stages": {},
            "ok": False,
        }
        if scene.label:
            self.summary.update(label=scene.label, sets=list(scene.sets))

    def name(self, stage: str) -> str:
        return f"{self.scene.label}/{stage}" if self.scene.label else stage


def made_with(store: Store, key: str | None, engine: str) -> tuple[str, str | None]:
    """(engine, device) a step's record says made its outputs: the engine the step chose itself when it
    resolved one (a depth stage's ``auto``), else ``engine``; (``used``, None) for a used file."""
    rec = store.record(key) if key else None
    if rec is None:
        return ("used", None) if key is None else (engine, None)
    chosen = chosen_engine(rec)
    return (chosen["engine"] if chosen else engine), rec["provenance"].get("device")


def finish_run(st: SceneRun, latest: bool) -> None:
    """Write the scene's final run.json (and move `latest` if asked), unless nothing changed since the
    latest run."""
    store, summary, ctx = st.ctx.store, st.summary, st.ctx
    if st.run_id is None:
        if not summary["stages"]:
            summary["run"] = None
            return
        last = store.run_info(store.latest_run_id())
        same = (
            last is not None
            and last.get("prompt") == ctx.prompt
            and {
                n: (s.get("key"), {k: v["digest"] for k, v in s.get("outputs", {}).items()})
                for n, s in last.get("stages", {}).items()
            }
            == {n: (e.get("key"), e["outputs"]) for n, e in summary["stages"].items()}
        )
        if same or not summary["ok"]:
            summary["run"] = store.latest_run_id() if same else None
            return
        st.run_id = store.new_run_id()
        for n in summary["stages"]:
            store.link_outputs(st.run_id, n, st.outputs[n])
    write_run(st, latest=latest)
    summary["run"] = st.run_id


def finish_batch(store: Store, states: list[SceneRun]) -> None:
    """A batch's runs are pinned (gc keeps every scene, not only the latest); `latest` -> the last one."""
    runs = [st.summary.get("run") for st in states if st.summary.get("run")]
    for rid in runs:
        store.pin(rid)
    if runs:
        store.write_run(runs[-1], store.run_info(runs[-1]), latest=True)


def write_run(st: SceneRun, latest: bool) -> None:
    ctx, summary = st.ctx, st.summary
    stages = {
        n: {
            "key": e.get("key"),
            "how": e["how"],
            "outputs": st.outputs[n],
            **{k: e[k] for k in ("source", "import") if k in e},
        }
        for n, e in summary["stages"].items()
    }
    info = {
        "run": st.run_id,
        "pipeline": str(ctx.pipe.path),
        "prompt": ctx.prompt,
        "profile": ctx.profile,
        "seed": ctx.seed,
        "ok": summary["ok"],
        "seconds": summary.get("seconds"),
        "stages": stages,
        "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    if st.scene.label:
        info.update(label=st.scene.label, sets=list(st.scene.sets))
    ctx.store.write_run(st.run_id, info, latest=latest)

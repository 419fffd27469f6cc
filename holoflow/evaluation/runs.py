"""Running the pipeline for one evaluated scene (served from the store when cached) and reading which
engines made a run's depth. The project is the checkout holding the holoflow package
(holoflow.flow.code_closure.HOLOFLOW_ROOT): its pipeline.yaml, and artifacts/ unless a store is given."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from holoflow.flow.code_closure import HOLOFLOW_ROOT

if TYPE_CHECKING:
    from holoflow.flow.store import Store


DEPTH_STAGES = ("base_pano", "tangent_depth", "metric_align")


def depth_engines(run_dir: Path) -> dict[str, str]:
    """stage -> what made it, for the stages that decide the depth (DEPTH_STAGES), from the run's
    run.json and the store's step records: the engine ("auto -> layout" where a chooser picked one),
    "used FILE" for a stage given by ``--use``, "unknown" where the record is missing."""
    from holoflow.flow.status import chosen_engine
    from holoflow.flow.store import Store

    store = Store(run_dir.parent.parent)  # runs/<id> lies in the store's root
    stages = (store.run_info(run_dir.name) or {}).get("stages", {})
    out = {}
    for name in DEPTH_STAGES:
        st = stages.get(name) or {}
        rec = store.record(st["key"]) if st.get("key") else None
        if st.get("how") == "used":
            out[name] = f"used {Path(st.get('source') or '?').name}"
        elif rec is None:
            out[name] = "unknown"
        else:
            engine, chosen = rec["provenance"].get("engine"), chosen_engine(rec)
            picked = chosen["engine"] if chosen else None
            out[name] = f"{engine} -> {picked}" if picked and picked != engine else str(engine)
    return out


def open_store(store: Path | None) -> "Store":
    """The store at ``store``, else $HOLOFLOW_STORE, else artifacts/ beside pipeline.yaml (as the CLI)."""
    import os

    from holoflow.flow.store import Store

    return Store(store or os.environ.get("HOLOFLOW_STORE") or (Path(HOLOFLOW_ROOT) / "artifacts"))


def run_pipeline(
    prompt: str, profile: str, sets: list[str], store: Path | None, uses: list[str] = ()
) -> tuple[Path, dict]:
    """Run (or reuse from the cache) the pipeline for ``prompt`` (``uses``: STAGE=PATH as ``--use``);
    returns (run folder, summary)."""
    import io

    from holoflow.flow import pipeline
    from holoflow.flow.context import BatchItem, Context, Options
    from holoflow.flow.progress import make_display
    from holoflow.flow.scheduler import run
    from holoflow.networks.manifest import prepare

    pipe = pipeline.load(Path(HOLOFLOW_ROOT) / "pipeline.yaml")
    st = open_store(store)
    opts = Options(prompt=prompt, profile=profile, sets=list(sets), uses=list(uses))
    ctx = Context.build(pipe, st, opts)
    prepare([BatchItem(ctx, opts)], None)
    summary = run(ctx, opts, make_display(io.StringIO(), fancy=False))
    return st.run_dir(summary["run"]), summary

"""What the report shows about a run, read from the store (docs/store.md): the run record
``runs/<id>/run.json``, each step's key record ``keys/<key>.json`` (engine, params, wall time, CPU time,
peak RSS, meta) and the files under ``runs/<id>/<stage>/``. Reads only; takes no lock (every file
read is replaced atomically by the runner).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from holoflow.flow.store import Store, read_json


class ReportError(Exception):
    """The run cannot be reported (no such run, no run.json): one line, with the fix."""


@dataclass
class StageInfo:
    """One stage of the pipeline as the run saw it; ``how`` is None when the run did not include it."""

    name: str
    how: str | None  # ran | cached | cut off | used | None (not run)
    key: str | None = None
    record: dict[str, Any] = field(default_factory=dict)  # the key record's provenance ({} if none)
    files: dict[str, Path] = field(default_factory=dict)  # output name -> path under runs/<id>/<stage>/
    missing: list[str] = field(default_factory=list)  # outputs in run.json whose file is gone (gc'd)

    @property
    def ran(self) -> bool:
        return self.how is not None


@dataclass
class RunInfo:
    run_id: str
    run_dir: Path
    meta: dict[str, Any]  # run.json without "stages"
    stages: list[StageInfo]  # pipeline order when the pipeline is known, else run.json order


def resolve_run(store: Store, run: str) -> Path:
    """runs/<id> of RUN (a run id, or 'latest')."""
    if run == "latest":
        link = store.root / "latest"
        if not link.exists():
            raise ReportError(f"store {store.root} has no latest run; fix: `holoflow run` first, or pass --store DIR")
        return link.resolve()
    path = store.run_dir(run)
    if not (path / "run.json").is_file():
        runs = sorted(p.name for p in (store.root / "runs").glob("*") if (p / "run.json").is_file())
        hint = f"; runs: {', '.join(runs[-5:])}" if runs else ""
        raise ReportError(f"no run {run!r} in {store.root}{hint}")
    return path


def collect(store: Store, run: str = "latest", order: list[str] | None = None) -> RunInfo:
    """The run's stages with their records and output files; stages of ``order`` (the pipeline's
    topological order) missing from the run are listed as not run."""
    run_dir = resolve_run(store, run)
    doc = read_json(run_dir / "run.json")
    if doc is None:
        raise ReportError(f"{run_dir / 'run.json'} is missing or unreadable")
    entries: dict[str, dict] = doc.get("stages", {})
    names = list(order or []) + [n for n in entries if n not in (order or [])]
    stages = [_stage(store, run_dir, n, entries.get(n)) for n in names]
    meta = {k: v for k, v in doc.items() if k != "stages"}
    return RunInfo(run_id=run_dir.name, run_dir=run_dir, meta=meta, stages=stages)


def _stage(store: Store, run_dir: Path, name: str, entry: dict | None) -> StageInfo:
    if entry is None:
        return StageInfo(name=name, how=None)
    key = entry.get("key")
    record = (read_json(store.key_path(key)) or {}) if key else {}
    folder = run_dir / name
    names = sorted(entry.get("outputs", {}))
    files = {rel: folder / rel for rel in names if (folder / rel).is_file()}
    return StageInfo(
        name=name,
        how=entry.get("how"),
        key=key,
        record=record.get("provenance", {}),
        files=files,
        missing=[rel for rel in names if rel not in files],
    )

"""Status: per stage, whether its cached result is fresh, stale or missing, and why in the user's words
(`holoflow status`, `run --dry-run`, docs/cli.md). Reads only small JSON records and stats sources.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .cachekey import cache_key, reasons
from .uses import IMAGE_EXTS, dropped_uses, import_cache

if TYPE_CHECKING:
    from .context import Context


def chosen_engine(rec: dict) -> dict | None:
    """The engine a step chose itself (a depth stage's ``auto``) as its record's @meta says:
    ``{"engine": NAME, "why": one line, ...}``; None for a step that ran the engine it was given."""
    meta = rec.get("provenance", {}).get("meta", {}).get("engine")
    return meta if isinstance(meta, dict) and meta.get("engine") else None


def engine_note(chosen: dict) -> str:
    """'engine NAME (why)' for a ``chosen_engine``."""
    return f"engine {chosen['engine']}" + (f" ({chosen['why']})" if chosen.get("why") else "")


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
            if s.primary and s.primary.endswith(".exr") and ctx.uses[name].suffix.lower() in (*IMAGE_EXTS, ".exr"):
                src_sha = outputs[name][s.primary]["digest"]
                outputs[name] = import_cache(ctx, src_sha) or outputs[name]  # the converted EXR's digest
            continue
        if s.prompt and ctx.prompt is None:
            out[name] = {
                "state": "missing",
                "key": None,
                "reasons": ['no prompt yet (holoflow status "PROMPT", or run once)'],
            }
            continue
        bad_up = [u for u in s.inputs.values() if u not in outputs]
        if bad_up:
            comp = ctx.components(name, {u: outputs.get(u, {}) for u in s.inputs.values()})
            own = [r for r in explain(ctx, name, comp) if not r.startswith("input changed")]
            own = [r for r in own if r not in ("never run", "key changed")]
            ups = sorted(set(bad_up), key=list(ctx.pipe.stages).index)
            never = store.last_key(name) is None
            out[name] = {
                "state": "missing" if never else "stale",
                "key": None,
                "reasons": (["never run"] if never else own) + [f"upstream not fresh: {', '.join(ups)}"],
            }
            continue
        comp = ctx.components(name, outputs)
        key = cache_key(comp)
        rec = store.record(key)
        if rec is not None:
            missing = [rel for rel, e in rec["outputs"].items() if not store.check(e)]
            if not missing:
                out[name] = {"state": "fresh", "reasons": [], "key": key, "ran": ran_info(rec)}
                chosen = chosen_engine(rec)
                if chosen is not None:
                    out[name]["engine"] = {"ran": chosen["engine"], "why": chosen.get("why", "")}
                outputs[name] = rec["outputs"]
                continue
            out[name] = {
                "state": "missing",
                "key": key,
                "reasons": [f"output missing or corrupted: {', '.join(missing[:3])}"],
            }
            continue
        why = explain(ctx, name, comp)
        out[name] = {"state": "missing" if why == ["never run"] else "stale", "reasons": why, "key": key}
    for name, source in dropped_uses(ctx).items():  # the latest run's own file is not in this view
        if name in out and out[name]["state"] != "fresh":
            out[name]["reasons"].append(
                f"the latest run used {source} (--use): "
                f"holoflow status --use {shlex.quote(f'{name}={source}')} shows that run"
            )
    ctx.hasher.save()
    return out


def ran_info(rec: dict) -> dict[str, Any]:
    """Where and with what a recorded step ran: host, executor, declared resources, wall, peak memory."""
    prov = rec.get("provenance", {})
    return {k: prov.get(k) for k in ("host", "executor", "resources", "attempt", "wall_s", "peak_rss_mb")}


def describe_ran(info: dict[str, Any] | None) -> str:
    """``ran_info`` in words: 'on vm (local; 1 cpu, 2 GB; 3.1 s, peak 210 MB)'."""
    if not info or not info.get("host"):
        return ""
    res = info.get("resources") or {}
    want = [f"{res.get('cpus', 1)} cpu"]
    if res.get("gpus"):
        want.append(f"{res['gpus']} gpu" + (f" #{res['gpu_ids']}" if res.get("gpu_ids") else ""))
    if res.get("memory_gb"):
        want.append(f"{res['memory_gb']:g} GB")
    used = [f"{info['wall_s']:.1f} s"] if info.get("wall_s") is not None else []
    if info.get("peak_rss_mb"):
        used.append(f"peak {info['peak_rss_mb']:.0f} MB")
    if (info.get("attempt") or 1) > 1:
        used.append(f"attempt {info['attempt']}")
    return f"on {info['host']} ({info.get('executor') or 'local'}; {', '.join(want)}; {', '.join(used)})"


def explain(ctx: Context, name: str, comp: dict) -> list[str]:
    last = ctx.store.last_key(name)
    rec = ctx.store.record(last) if last else None
    if rec is None:
        return ["never run"]
    return reasons(rec["components"], comp)


def _digests_of(path: Path, primary: str | None) -> dict[str, dict]:
    from .store import sha256_file

    if path.is_dir():
        return {
            p.relative_to(path).as_posix(): {"digest": sha256_file(p)} for p in sorted(path.rglob("*")) if p.is_file()
        }
    return {primary or path.name: {"digest": sha256_file(path)}}

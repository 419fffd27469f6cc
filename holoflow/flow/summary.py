"""The text summary of a run, a batch or a sweep (`holoflow run`, `run --prompts`, `sweep`; --json prints
the same dicts as JSON instead)."""

from __future__ import annotations

import json
from typing import Any

from .store import Store


def summary_lines(result: dict[str, Any], store: Store) -> list[str]:
    """``result``: one scene's summary (``runner.run``) or a batch's (``runner.run_batch``: ``scenes``),
    either of them a dry run; returns its lines."""
    batch = "scenes" in result
    scenes = result["scenes"] if batch else [result]
    if result.get("dry_run"):
        lines = []
        for sc in scenes:
            label = f"{sc.get('label', ''):<4} " if batch else ""
            for name, st in sc["stages"].items():
                why = f"  ({'; '.join(st['reasons'])})" if st["reasons"] else ""
                lines.append(f"{label}{name:<16} {st['how']:<8}{why}")
        return lines
    if not batch:
        where = f"; outputs in {store.run_dir(result['run'])}" if result.get("run") else ""
        return [f"holoflow: done in {result['seconds']:.2f} s ({_counts(result) or 'nothing selected'}){where}"]
    lines = []
    for sc in scenes:
        sets = f" [{' '.join(sc['sets'])}]" if sc.get("sets") else ""
        lines.append(
            f"{sc['label']}: {_counts(sc) or 'nothing'}; run {sc.get('run')}; {json.dumps(sc['prompt'])}{sets}"
        )
    lines.append(
        f"holoflow: batch of {len(scenes)} scenes done in {result['seconds']:.2f} s "
        f"({result.get('executor', 'all cached')}); runs pinned, latest -> the last scene"
    )
    return lines


def _counts(scene: dict[str, Any]) -> str:
    """'2 cached, 1 ran': how many of the scene's stages were served which way, in order of first use."""
    counts: dict[str, int] = {}
    for st in scene["stages"].values():
        counts[st["how"]] = counts.get(st["how"], 0) + 1
    return ", ".join(f"{n} {how}" for how, n in counts.items())

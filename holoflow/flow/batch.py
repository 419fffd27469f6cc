"""Batches of scenes: ``holoflow run --prompts FILE`` and ``holoflow sweep`` (docs/scale.md).

A prompts file is either plain text (one prompt per line; blank lines and ``#`` comments skipped) or,
for a ``.yaml`` / ``.yml`` file, a YAML list whose items are a prompt string or a mapping
``{prompt: TEXT, set: {STAGE.PARAM: VALUE, ...}, seed: N}`` (``set`` may also be a list of
``STAGE.PARAM=VALUE`` strings). A sweep is the grid (cartesian product) of ``--grid
STAGE.PARAM=V1,V2,...`` axes (or a YAML list: ``--grid 'tangent_depth.grid=[[8, 7], [4, 4]]'``) over
each prompt. Every scene is one run over the same store; their steps share cache entries wherever the
keys agree, so e.g. a sweep over a late stage's param computes the early stages once.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .context import BatchItem, Context, Options
from .pipeline import Pipeline, PipelineError
from .store import Store


@dataclass
class SceneSpec:
    """One scene of a batch: its prompt, its own ``--set`` items, and an optional seed."""

    prompt: str | None
    sets: list[str] = field(default_factory=list)
    seed: int | None = None


def yaml_value(value: Any) -> str:
    """``value`` as YAML text that ``--set`` parses back to the same value (incl. .inf / .nan)."""
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    if isinstance(value, list):
        return "[" + ", ".join(yaml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))}: {yaml_value(v)}" for k, v in value.items()) + "}"
    return json.dumps(value)


def read_prompts(path: str | Path) -> list[SceneSpec]:
    """Scenes from a prompts file (text: one per line; .yaml/.yml: a list, see the module doc)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise PipelineError(f"--prompts {path}: cannot read it ({e.strerror}); fix: check the path") from None
    if path.suffix.lower() not in (".yaml", ".yml"):
        scenes = [
            SceneSpec(line.strip()) for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")
        ]
    else:
        import yaml

        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as e:
            raise PipelineError(
                f"--prompts {path}: not valid YAML ({str(e).splitlines()[0]}); fix: write a "
                f"list of prompts or of {{prompt: ..., set: {{...}}}}"
            ) from None
        if not isinstance(doc, list):
            raise PipelineError(f"--prompts {path}: the top level must be a list; fix: start each scene with '- '")
        scenes = [_scene_item(path, i, item) for i, item in enumerate(doc, 1)]
    if not scenes:
        raise PipelineError(f"--prompts {path}: no prompts in it; fix: one prompt per line")
    return scenes


def _scene_item(path: Path, i: int, item: Any) -> SceneSpec:
    if isinstance(item, str):
        return SceneSpec(item)
    if not isinstance(item, dict) or set(item) - {"prompt", "set", "seed"}:
        raise PipelineError(
            f"--prompts {path}: item {i} must be a prompt or a mapping with keys prompt, set, "
            f"seed; fix: e.g. '- {{prompt: a cabin, set: {{detail.strength: 0.7}}}}'"
        )
    prompt = item.get("prompt")
    if prompt is not None and not isinstance(prompt, str):
        raise PipelineError(f"--prompts {path}: item {i}: prompt is not text; fix: quote it")
    seed = item.get("seed")
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
        raise PipelineError(f"--prompts {path}: item {i}: seed {seed!r} is not an integer; fix: e.g. seed: 3")
    raw = item.get("set") or {}
    if isinstance(raw, dict):
        sets = [f"{k}={yaml_value(v)}" for k, v in raw.items()]
    elif isinstance(raw, list) and all(isinstance(s, str) for s in raw):
        sets = list(raw)
    else:
        raise PipelineError(
            f"--prompts {path}: item {i}: set must be a mapping STAGE.PARAM: VALUE; fix: e.g. "
            f"set: {{detail.strength: 0.7}}"
        )
    return SceneSpec(prompt, sets, seed)


def grid_axis(item: str) -> tuple[str, list[str]]:
    """``STAGE.PARAM=V1,V2`` or ``STAGE.PARAM=[V1, V2]`` -> (STAGE.PARAM, [set values as YAML text])."""
    if "=" not in item or "." not in item.split("=", 1)[0]:
        raise PipelineError(
            f"--grid {item!r}: expected STAGE.PARAM=V1,V2,...; fix: e.g. --grid detail.strength=0.3,0.5,0.7"
        )
    lhs, text = item.split("=", 1)
    if text.lstrip().startswith("["):
        import yaml

        try:
            values = yaml.safe_load(text)
        except yaml.YAMLError:
            values = None
        if not isinstance(values, list) or not values:
            raise PipelineError(
                f"--grid {item!r}: not a YAML list of values; fix: e.g. --grid 'tangent_depth.grid=[[8, 7], [4, 4]]'"
            )
        return lhs, [yaml_value(v) for v in values]
    values = [v.strip() for v in text.split(",")]
    if not all(values):
        raise PipelineError(f"--grid {item!r}: an empty value; fix: list values separated by commas")
    return lhs, values


def sweep(prompts: list[SceneSpec], grid: list[str]) -> list[SceneSpec]:
    """Every prompt scene x every point of the grid (axes in the order given; last varies fastest)."""
    axes = [grid_axis(g) for g in grid]
    names = [a for a, _ in axes]
    if len(set(names)) != len(names):
        raise PipelineError(
            f"--grid names {', '.join(n for n in names if names.count(n) > 1)} twice; fix: give each param one --grid"
        )
    out = []
    for p in prompts:
        for point in itertools.product(*(vals for _, vals in axes)):
            out.append(replace(p, sets=p.sets + [f"{n}={v}" for n, v in zip(names, point)]))
    return out


# -- scenes for the runner -------------------------------------------------------------------------
def make_scenes(pipe: Pipeline, store: Store, base: Options, specs: list[SceneSpec]) -> list[BatchItem]:
    """One labelled scene (s1, s2, ...) per spec: ``base`` options with the spec's prompt and seed (when
    given) and its ``--set`` items after the base ones; the scenes share one code hasher."""
    scenes = []
    hasher = None
    for i, spec in enumerate(specs, 1):
        opts = replace(
            base,
            prompt=spec.prompt if spec.prompt is not None else base.prompt,
            sets=list(base.sets) + spec.sets,
            seed=spec.seed if spec.seed is not None else base.seed,
        )
        try:
            ctx = Context.build(pipe, store, opts, hasher=hasher)
        except PipelineError as e:
            raise PipelineError(f"scene s{i}: {e}") from None
        hasher = ctx.hasher
        scenes.append(BatchItem(ctx, opts, label=f"s{i}", sets=spec.sets))
    return scenes

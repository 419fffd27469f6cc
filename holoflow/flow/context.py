"""The run context: a run's options (``holoflow run``'s flags), and everything a run or a status check
needs resolved once from them (params, device, prompt, seed, ``--use`` files, the code hasher).
Imports nothing heavy and no domain package."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .cachekey import CodeHasher, components, tree_digest
from .pipeline import Pipeline, PipelineError, Resolved, profile_device, resolve
from .store import Store


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
    jobs: int = 1  # -j: CPU slots of the local executor (local Ray: its CPUs)
    executor: str = "local"  # local | ray
    address: str | None = None  # Ray cluster address (ray executor)
    connect_timeout: float | None = None  # seconds to wait for the cluster at address (None: 60)
    retries: int | None = None  # extra attempts per failed step (None: the executor's default)
    cold: bool = False  # --cold: exec every local step (no warm template)


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
        uses = parse_uses(pipe, opts.uses)
        prompt = opts.prompt
        if prompt is None:
            info = store.run_info(store.latest_run_id())
            prompt = info.get("prompt") if info else None
        seed = pipe.seed if opts.seed is None else opts.seed
        hasher = hasher or CodeHasher(pipe.root, store.root / "cache" / "code.json")
        return cls(
            pipe,
            store,
            resolved,
            seed,
            prompt,
            opts.profile or pipe.default_profile,
            uses,
            hasher,
            device,
            opts.verbose,
        )

    def components(self, name: str, outputs: dict[str, dict]) -> dict[str, Any]:
        """Key components of stage ``name`` given its upstream stages' outputs."""
        s = self.pipe.stages[name]
        r = self.resolved[name]
        code = {
            **self.hasher.closure(self.pipe.program(name)),
            **self.hasher.version([self.pipe.path_of(c) for c in s.code]),
        }
        inputs = {inp: {"stage": up, "tree": tree_digest(outputs[up])} for inp, up in s.inputs.items()}
        prompt = None
        if s.prompt:
            if self.prompt is None:
                raise PipelineError(
                    f"stage '{name}' needs a prompt and no earlier run gave one; fix: "
                    f'holoflow run "a small wooden cabin"'
                )
            prompt = self.prompt
        return components(name, code, r.engine, r.params, inputs, self.seed, prompt)


@dataclass
class BatchItem:
    """One item of a run or batch (one scene): its context (prompt, resolved params, seed) and run options."""

    ctx: Context
    opts: Options
    label: str = ""  # "" for a single run; "s1", "s2", ... in a batch
    sets: list[str] = field(default_factory=list)  # the scene's own --set (for the summary)


def parse_uses(pipe: Pipeline, uses: list[str]) -> dict[str, Path]:
    out = {}
    for item in uses:
        if "=" not in item:
            raise PipelineError(f"--use {item!r}: expected STAGE=PATH; fix: e.g. --use base_pano=my_pano.exr")
        stage, path = item.split("=", 1)
        if stage not in pipe.stages:
            raise PipelineError(f"--use {item!r}: unknown stage '{stage}'; fix: use one of: {', '.join(pipe.stages)}")
        p = Path(path).expanduser().absolute()
        if not p.exists():
            raise PipelineError(f"--use {stage}={path}: no such file or folder; fix: check the path")
        out[stage] = p
    return out


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
        raise PipelineError(
            f"profile '{opts.profile}' asks for device cuda and this machine has no CUDA "
            f"device; fix: run it on a GPU machine, or add --device cpu (slow at full size)"
        )
    return asked


def resolve_device_engines(resolved: dict[str, Resolved], device: str) -> None:
    """An engine that the stage's registry picks by device (``Engines(on_device=...)``: the splat
    stages' ``auto``) becomes the engine it names for ``device``, before the cache key is made: the key
    names the engine that really runs."""
    for r in resolved.values():
        engines = r.stage.config.ENGINES if r.stage.config is not None else None
        picked = engines.for_device(r.engine, device) if engines is not None else None
        if picked is not None:
            r.overrides["engine"] = f"{r.engine} on {device}"
            r.engine = picked


def cuda_present() -> bool:
    """An NVIDIA driver is loaded (checked without importing torch; the step itself still decides)."""
    return os.path.exists("/proc/driver/nvidia/version") or os.path.exists("/dev/nvidia0")


def select(pipe: Pipeline, opts: Options, uses: dict[str, Path]) -> tuple[set[str], set[str], set[str]]:
    """(selected: may run, needed: must be available, forced) from --from/--until/--only/--force/--use.
    A stage whose outputs only --use'd stages read is neither: nothing in the run needs it."""
    for flag, name in (
        ("--from", opts.from_stage),
        ("--until", opts.until),
        ("--only", opts.only),
        *(("--force", f) for f in opts.force if f != "all"),
    ):
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
        raise PipelineError(
            f"--force {', '.join(sorted(forced - selected))}: not among the stages this run "
            f"covers ({', '.join(s for s in pipe.stages if s in selected)}); fix: widen "
            f"--from/--until/--only"
        )
    # what the run is for: its last selected stages and the ones named on the command line; a stage
    # only --use'd stages read (tangent_depth under --use metric_align=...) has nothing to do
    named = {n for n in (opts.from_stage, opts.until, opts.only, *opts.force) if n and n != "all"}
    read = {up for n in selected for up in pipe.stages[n].inputs.values()}
    targets = {n for n in selected if n not in read} | (named & selected) | forced
    needed: set[str] = set()
    stack = list(targets)
    while stack:
        n = stack.pop()
        if n in needed:
            continue
        needed.add(n)
        if n not in uses:
            stack.extend(pipe.stages[n].inputs.values())
    return selected & needed, needed, forced


# -- running -------------------------------------------------------------------------------------

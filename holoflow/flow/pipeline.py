"""Load and validate pipeline.yaml; resolve a profile and ``--set`` overrides into per-stage configs.

Every user mistake raises :class:`PipelineError` whose message is one line naming the file, the stage
(when there is one) and the fix. Nothing here imports more than the standard library and PyYAML.

Schema (docs/cli.md has the user-facing version)::

    version: 1
    seed: 0                       # int; every random choice of every stage derives from it
    default_profile: preview      # optional; must name a profile
    stages:
      NAME:                       # [A-Za-z_][A-Za-z0-9_]*
        run: stages/x.py          # program, relative to pipeline.yaml's folder
        engine: classical         # the default engine; must be listed in engines
        engines: [classical, ...] # optional; default [engine]
        prompt: true              # optional bool; the prompt is part of the cache key
        inputs: {pano: upscale}   # optional; input name -> upstream stage
        code: [holoflow/imageops] # optional; files/folders whose source is part of the cache key
        primary: pano.exr         # optional; name a single `--use` file takes in the stage's outputs
        config: holoflow.imageops.config:DetailParams   # optional; the stage's typed parameter class
        params: {strength: 0.5}   # optional; with `config:` overrides of the class's defaults, checked
                                  # by the class; without, the defaults (their types checked on override)
        resources: {cpus: 1, gpus: 0, memory_gb: 2}   # optional; what one step needs (scheduling)
    profiles:
      NAME: {device: auto, STAGE: {engine: X, PARAM: VALUE, resources: {gpus: 1}}}

A profile's optional ``device`` (cpu | cuda | auto) is the device its steps ask for; ``--device`` and
$HOLOFLOW_DEVICE win over it. ``--profile a,b`` applies a, then b, in order: for each stage, b's
engine / params / resources replace a's key by key (a key b does not name keeps a's value), and the
last profile naming a device wins.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .params import ParamError, article, coerce_like, is_int, kind, load_class, suggest

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TOP_KEYS = {"version", "seed", "default_profile", "stages", "profiles"}
_STAGE_KEYS = {"run", "engine", "engines", "prompt", "inputs", "code", "primary", "config", "params", "resources"}
_RESOURCE_KEYS = {"cpus": int, "gpus": int, "memory_gb": float}
DEVICES = ("cpu", "cuda", "auto")
SUPPORTED_VERSIONS = (1,)


class PipelineError(Exception):
    """A mistake in pipeline.yaml, a profile, ``--set`` or ``--use``: one line, with the fix."""


@dataclass(frozen=True)
class Resources:
    """What one step of a stage needs while it runs: scheduling only, never part of the cache key.

    ``cpus``: threads the step may use (its OMP/MKL/OpenBLAS/numba thread count); ``gpus``: whole GPUs
    (a GPU stage never shares one); ``memory_gb``: peak resident memory, GiB (0 = unknown/small).
    """

    cpus: int = 1
    gpus: int = 0
    memory_gb: float = 0.0

    def replace(self, **over: Any) -> "Resources":
        return Resources(**{**self.as_dict(), **over})

    def as_dict(self) -> dict[str, Any]:
        return {"cpus": self.cpus, "gpus": self.gpus, "memory_gb": self.memory_gb}


@dataclass(frozen=True)
class Stage:
    """One stage as declared in pipeline.yaml (before a profile is applied)."""

    name: str
    run: str  # program path relative to the pipeline's folder
    engine: str
    engines: tuple[str, ...]
    prompt: bool
    inputs: dict[str, str]  # input name -> upstream stage
    code: tuple[str, ...]  # paths relative to the pipeline's folder
    params: dict[str, Any]  # every param's default (the class's, with `params:` applied)
    primary: str | None = None
    resources: Resources = Resources()
    config: Any = None  # the StageParams class named by `config:` (holoflow/flow/params.py), or None


@dataclass
class Pipeline:
    path: Path  # pipeline.yaml, absolute
    version: int
    seed: int
    default_profile: str | None
    stages: dict[str, Stage]  # in topological order
    profiles: dict[str, dict[str, dict[str, Any]]]
    profile_devices: dict[str, str] = field(default_factory=dict)  # profile -> cpu | cuda | auto

    @property
    def root(self) -> Path:
        return self.path.parent

    def program(self, stage: str) -> Path:
        return self.path_of(self.stages[stage].run)

    def path_of(self, rel: str) -> Path:
        """A path from pipeline.yaml, relative to its folder, normalised (symlinks kept)."""
        import os

        return Path(os.path.normpath(self.root / rel))

    def downstream(self, names: set[str]) -> set[str]:
        """``names`` and every stage that depends on one of them, transitively."""
        out = set(names)
        for s in self.stages.values():  # topological order: one pass suffices
            if any(up in out for up in s.inputs.values()):
                out.add(s.name)
        return out

    def upstream(self, names: set[str]) -> set[str]:
        """``names`` and every stage they depend on, transitively."""
        out = set(names)
        for s in reversed(list(self.stages.values())):
            if s.name in out:
                out.update(s.inputs.values())
        return out


@dataclass
class Resolved:
    """A stage's engine and params after the profile and ``--set``."""

    stage: Stage
    engine: str
    params: dict[str, Any]
    overrides: dict[str, str] = field(default_factory=dict)  # param -> where it was set
    resources: Resources = Resources()


def _err(path: Path, stage: str | None, msg: str, fix: str) -> PipelineError:
    where = f"{path.name}: stage '{stage}': " if stage else f"{path.name}: "
    return PipelineError(f"{where}{msg}; fix: {fix}")


def find_pipeline(given: str) -> Path:
    """The pipeline file; the default name is also looked for in parent folders (like git)."""
    path = Path(given).absolute()
    if given == "pipeline.yaml" and not path.exists():
        for parent in path.parent.parents:
            if (parent / given).is_file():
                return parent / given
    return path


def load(path: str | Path, cache_dir: Path | None = None) -> Pipeline:
    """Read and validate pipeline.yaml. Raises PipelineError (one line) on any mistake.

    With ``cache_dir``, the parsed document is cached as JSON keyed by the file's (size, mtime_ns),
    so an unchanged pipeline costs no YAML parsing (validation still runs).
    """
    path = Path(path).absolute()
    if not path.is_file():
        raise PipelineError(f"{path}: no such pipeline file; fix: run from the project folder or pass --pipeline FILE")
    doc = _parse_cached(path, cache_dir)
    return _validate(path, doc)


def _parse_cached(path: Path, cache_dir: Path | None) -> Any:
    import json

    st = path.stat()
    stamp = [str(path), st.st_size, st.st_mtime_ns]
    cache = cache_dir / "pipeline.json" if cache_dir is not None else None
    if cache is not None:
        try:
            hit = json.loads(cache.read_text())
            if hit.get("stamp") == stamp:
                return hit["doc"]
        except (OSError, ValueError):
            pass
    doc = _parse(path)
    if cache is not None and cache_dir.is_dir():
        from .store import write_atomic

        try:
            write_atomic(cache, json.dumps({"stamp": stamp, "doc": doc}))
        except (OSError, TypeError, ValueError):
            pass  # a cache only (a YAML document JSON cannot hold is simply not cached)
    return doc


def _parse(path: Path) -> Any:
    import yaml

    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise PipelineError(
            f"{path.name}: not valid YAML{where}: {problem}; fix: correct the syntax "
            f"there (indentation, quotes, colons)"
        ) from None
    except UnicodeDecodeError:
        raise PipelineError(f"{path.name}: not a UTF-8 text file; fix: save it as UTF-8") from None


def _validate(path: Path, doc: Any) -> Pipeline:
    if not isinstance(doc, dict):
        raise _err(
            path, None, f"top level is {kind(doc)}, not a mapping", "start with `version: 1` and a `stages:` mapping"
        )
    for key in doc:
        if key not in _TOP_KEYS:
            raise _err(
                path,
                None,
                f"unknown top-level key '{key}'",
                f"use only {', '.join(sorted(_TOP_KEYS))}{suggest(key, _TOP_KEYS)}",
            )
    version = doc.get("version")
    if version not in SUPPORTED_VERSIONS:
        raise _err(path, None, f"version is {version!r}", "set `version: 1`")
    seed = doc.get("seed", 0)
    if not is_int(seed):
        raise _err(path, None, f"seed is {seed!r} ({kind(seed)})", "set `seed:` to an integer")
    raw_stages = doc.get("stages")
    if not isinstance(raw_stages, dict) or not raw_stages:
        raise _err(path, None, "no `stages:` mapping", "add `stages:` with at least one stage")
    stages = {}
    for name, block in raw_stages.items():
        stages[name] = _stage(path, name, block)
    for s in stages.values():
        for inp, up in s.inputs.items():
            if up not in stages:
                raise _err(
                    path,
                    s.name,
                    f"input '{inp}' names unknown stage '{up}'",
                    f"name one of: {', '.join(stages)}{suggest(up, stages)}",
                )
            if up == s.name:
                raise _err(
                    path,
                    s.name,
                    f"input '{inp}' names the stage itself",
                    "a stage cannot read its own outputs; name an upstream stage",
                )
    ordered = _toposort(path, stages)
    profiles, devices = _profiles(path, doc.get("profiles"), stages)
    default_profile = doc.get("default_profile")
    if default_profile is not None and default_profile not in profiles:
        raise _err(
            path,
            None,
            f"default_profile '{default_profile}' is not a profile",
            f"define it under `profiles:` or use one of: {', '.join(profiles) or '(none)'}",
        )
    return Pipeline(path, version, int(seed), default_profile, ordered, profiles, devices)


def _stage(path: Path, name: Any, block: Any) -> Stage:
    if not isinstance(name, str) or not _NAME.match(name):
        raise _err(path, str(name), "invalid stage name", "use letters, digits and _ (not first digit)")
    if not isinstance(block, dict):
        raise _err(path, name, f"block is {kind(block)}, not a mapping", "give it `run:`, `engine:` and `params:` keys")
    for key in block:
        if key not in _STAGE_KEYS:
            raise _err(
                path,
                name,
                f"unknown key '{key}'",
                f"use only {', '.join(sorted(_STAGE_KEYS))}{suggest(key, _STAGE_KEYS)}",
            )
    run = block.get("run")
    if not isinstance(run, str) or not run.strip():
        raise _err(path, name, "missing `run:`", "set `run:` to the stage program, e.g. stages/NAME.py")
    engine = block.get("engine", "default")
    if not isinstance(engine, str) or not engine:
        raise _err(path, name, f"engine is {engine!r}", "set `engine:` to a name (string)")
    engines = block.get("engines", [engine])
    if not isinstance(engines, list) or not engines or not all(isinstance(e, str) and e for e in engines):
        raise _err(path, name, "`engines:` is not a list of names", "write e.g. `engines: [classical, model]`")
    if engine not in engines:
        raise _err(
            path, name, f"engine '{engine}' is not in engines {engines}", "add it to `engines:` or pick a listed one"
        )
    prompt = block.get("prompt", False)
    if not isinstance(prompt, bool):
        raise _err(path, name, f"`prompt:` is {prompt!r}", "write `prompt: true` or `prompt: false`")
    inputs = block.get("inputs", {}) or {}
    if not isinstance(inputs, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in inputs.items()):
        raise _err(
            path, name, "`inputs:` is not a mapping of input name -> stage", "write e.g. `inputs: {pano: upscale}`"
        )
    for inp in inputs:
        if not _NAME.match(inp):
            raise _err(path, name, f"invalid input name '{inp}'", "use letters, digits and _")
    code = block.get("code", []) or []
    if isinstance(code, str):
        code = [code]
    if not isinstance(code, list) or not all(isinstance(c, str) and c for c in code):
        raise _err(path, name, "`code:` is not a list of paths", "write e.g. `code: [holoflow/io]`")
    params = block.get("params", {}) or {}
    if not isinstance(params, dict):
        raise _err(path, name, f"`params:` is {kind(params)}, not a mapping", "write `params: {key: value}`")
    for p in params:
        if not isinstance(p, str) or not _NAME.match(p) or p == "engine":
            raise _err(path, name, f"invalid param name {p!r}", "use letters, digits and _; `engine` is reserved")
    config = _config_class(path, name, block.get("config"))
    if config is not None:
        for e in engines:
            if e not in config.ENGINES.names:
                raise _err(
                    path,
                    name,
                    f"engine '{e}' is not registered for {config.__name__}",
                    f"use one of: {', '.join(config.ENGINES.names)}{suggest(e, config.ENGINES.names)}",
                )
        params = {
            **config.defaults(),
            **{k: _param_checked(path, name, config, k, v, "`params:`") for k, v in params.items()},
        }
    primary = block.get("primary")
    if primary is not None and (not isinstance(primary, str) or not primary or "/" in primary):
        raise _err(path, name, f"`primary:` is {primary!r}", "name one output file, e.g. `primary: pano.exr`")
    resources = _resources(path, name, block.get("resources"), Resources(), "`resources:`")
    return Stage(
        name, run, engine, tuple(engines), prompt, dict(inputs), tuple(code), dict(params), primary, resources, config
    )


def _config_class(path: Path, stage: str, spec: Any):
    """The StageParams class of ``config: module:Class`` (None when the key is absent)."""
    if spec is None:
        return None
    if not isinstance(spec, str) or ":" not in spec:
        raise _err(path, stage, f"`config:` is {spec!r}", "write `config: package.module:ClassName`")
    try:
        return load_class(spec)
    except (ImportError, AttributeError) as e:
        raise _err(
            path,
            stage,
            f"`config: {spec}` cannot be loaded ({e})",
            "name a StageParams class, e.g. holoflow.recon.config:PreOptParams",
        ) from None


def _param_checked(path: Path, stage: str, config, key: str, value: Any, origin: str) -> Any:
    """``value`` checked by the stage's param class (type, range, known name), canonical type."""
    try:
        value = config.check(key, value)
    except ParamError as e:
        raise _err(path, stage, f"{origin} sets {e.msg}", e.fix) from None
    return list(value) if isinstance(value, tuple) else value  # the plain form hashed into the key


def _resources(path: Path, stage: str, raw: Any, base: Resources, origin: str) -> Resources:
    """``base`` with the keys of mapping ``raw`` (cpus >= 1, gpus >= 0 integers, memory_gb >= 0)."""
    if raw is None:
        return base
    if not isinstance(raw, dict):
        raise _err(
            path,
            stage,
            f"{origin} is {kind(raw)}, not a mapping",
            "write e.g. `resources: {cpus: 1, gpus: 0, memory_gb: 2}`",
        )
    over = {}
    for key, value in raw.items():
        if key not in _RESOURCE_KEYS:
            raise _err(
                path,
                stage,
                f"{origin} has unknown key '{key}'",
                f"use only {', '.join(_RESOURCE_KEYS)}{suggest(str(key), _RESOURCE_KEYS)}",
            )
        ok = (
            is_int(value)
            if _RESOURCE_KEYS[key] is int
            else isinstance(value, (int, float)) and not isinstance(value, bool) and value == value
        )
        low = 1 if key == "cpus" else 0
        if not ok or value < low or value == float("inf"):
            want = "an integer" if _RESOURCE_KEYS[key] is int else "a number"
            raise _err(path, stage, f"{origin} sets {key}={value!r}", f"give {key} {want} >= {low}")
        over[key] = _RESOURCE_KEYS[key](value)
    return base.replace(**over)


def check_files(pipe: Pipeline, name: str) -> None:
    """The stage's program and code paths exist (checked only for stages a run needs)."""
    s = pipe.stages[name]
    prog = pipe.program(name)
    if not prog.is_file():
        raise _err(
            pipe.path,
            name,
            f"program '{s.run}' does not exist",
            f"write it, or point `run:` at an existing program (relative to {pipe.root})",
        )
    if prog.suffix != ".py" and not _executable(prog):
        raise _err(pipe.path, name, f"program '{s.run}' is not executable", f"chmod +x {s.run}, or use a .py file")
    for c in s.code:
        if not (pipe.root / c).exists():
            raise _err(
                pipe.path,
                name,
                f"code path '{c}' does not exist",
                f"fix the path (relative to {pipe.root}) or remove it from `code:`",
            )


def _executable(p: Path) -> bool:
    import os

    return os.access(p, os.X_OK)


def _toposort(path: Path, stages: dict[str, Stage]) -> dict[str, Stage]:
    """Stages in a topological order (stable: declaration order among ready stages)."""
    done: dict[str, Stage] = {}
    pending = dict(stages)
    while pending:
        ready = [n for n, s in pending.items() if all(u in done for u in s.inputs.values())]
        if not ready:
            cycle = _find_cycle(pending)
            raise _err(
                path,
                cycle[0],
                f"inputs form a cycle: {' -> '.join(cycle)}",
                "remove one of those inputs; the pipeline must be a DAG",
            )
        for n in ready:
            done[n] = pending.pop(n)
    return done


def _find_cycle(pending: dict[str, Stage]) -> list[str]:
    node = next(iter(pending))
    seen: list[str] = []
    while node not in seen:
        seen.append(node)
        node = next(u for u in pending[node].inputs.values() if u in pending)
    return seen[seen.index(node) :] + [node]


def _profiles(
    path: Path, raw: Any, stages: dict[str, Stage]
) -> tuple[dict[str, dict[str, dict[str, Any]]], dict[str, str]]:
    """({profile: {stage: overrides}}, {profile: device}) of the ``profiles:`` block."""
    if raw is None:
        return {}, {}
    if not isinstance(raw, dict):
        raise _err(path, None, "`profiles:` is not a mapping", "write `profiles: {NAME: {STAGE: {param: value}}}`")
    out, devices = {}, {}
    for pname, block in raw.items():
        block = block or {}
        if not isinstance(block, dict):
            raise _err(
                path,
                None,
                f"profile '{pname}' is not a mapping of stage -> overrides",
                f"write `{pname}: {{STAGE: {{param: value}}}}`",
            )
        block = dict(block)
        if "," in str(pname):
            raise _err(path, None, f"profile name '{pname}' holds a comma", "`--profile a,b` lists profiles; rename it")
        if "device" in block:
            device = block.pop("device")
            if device not in DEVICES:
                raise _err(
                    path, None, f"profile '{pname}' asks for device {device!r}", f"use one of: {', '.join(DEVICES)}"
                )
            devices[str(pname)] = device
        prof = {}
        for sname, over in block.items():
            if sname not in stages:
                raise _err(
                    path,
                    None,
                    f"profile '{pname}' names unknown stage '{sname}'",
                    f"use one of: {', '.join(stages)}{suggest(sname, stages)}",
                )
            over = over or {}
            if not isinstance(over, dict):
                raise _err(
                    path, sname, f"profile '{pname}' overrides are not a mapping", "write `STAGE: {param: value}`"
                )
            for key, value in over.items():
                _check_override(path, stages[sname], key, value, f"profile '{pname}'")
            prof[sname] = dict(over)
        out[str(pname)] = prof
    return out, devices


def _check_override(path: Path, stage: Stage, key: str, value: Any, origin: str) -> Any:
    """Validate one override; returns the value in its canonical type (int -> float for float params)."""
    if key == "resources":  # validated here; merged over the stage's current resources in _apply
        _resources(path, stage.name, value, stage.resources, f"{origin} resources")
        return {k: _RESOURCE_KEYS[k](v) for k, v in value.items()}
    if key == "engine":
        if value not in stage.engines:
            raise _err(
                path,
                stage.name,
                f"{origin} sets engine '{value}', not one of {list(stage.engines)}",
                f"pick one of {', '.join(stage.engines)}{suggest(str(value), stage.engines)}",
            )
        return value
    if stage.config is not None:
        return _param_checked(path, stage.name, stage.config, key, value, origin)
    if key not in stage.params:
        raise _err(
            path,
            stage.name,
            f"{origin} sets unknown param '{key}'",
            f"params are: {', '.join(stage.params) or '(none)'}{suggest(key, stage.params)}",
        )
    ok, coerced = coerce_like(stage.params[key], value)
    if not ok:
        raise _err(
            path,
            stage.name,
            f"{origin} sets {key}={value!r} ({kind(value)}), but the default "
            f"{stage.params[key]!r} is {kind(stage.params[key])}",
            f"give {key} {article(type(stage.params[key]))} value",
        )
    return coerced


def resolve(pipe: Pipeline, profile: str | None = None, sets: list[str] | tuple[str, ...] = ()) -> dict[str, Resolved]:
    """Engine and params per stage: defaults, then ``profile`` (or the default profile), then ``sets``.

    ``sets`` are ``stage.param=value`` strings, the value parsed as YAML (``0.7``, ``[4, 4]``, ``true``);
    ``stage.engine=NAME`` picks an engine.
    """
    out = {}
    for s in pipe.stages.values():
        out[s.name] = Resolved(s, s.engine, dict(s.params), resources=s.resources)
    for name in profile_list(pipe, profile):
        for sname, over in pipe.profiles[name].items():
            for key, value in over.items():
                _apply(
                    out[sname],
                    key,
                    _check_override(pipe.path, out[sname].stage, key, value, f"profile '{name}'"),
                    f"profile {name}",
                )
    for item in sets:
        if "=" not in item or "." not in item.split("=", 1)[0]:
            raise PipelineError(f"--set {item!r}: expected STAGE.PARAM=VALUE; fix: e.g. --set detail.strength=0.7")
        lhs, text = item.split("=", 1)
        sname, key = lhs.split(".", 1)
        if sname not in out:
            raise PipelineError(
                f"--set {item!r}: unknown stage '{sname}'; fix: use one of: {', '.join(out)}{suggest(sname, out)}"
            )
        import yaml

        try:
            value = yaml.safe_load(text) if text.strip() else ""
        except yaml.YAMLError:
            value = text
        # A bare word that YAML reads as a non-string stays a string when the param is a string.
        if (
            key in out[sname].stage.params
            and isinstance(out[sname].stage.params[key], str)
            and not isinstance(value, str)
        ):
            value = text
        _apply(out[sname], key, _check_override(pipe.path, out[sname].stage, key, value, "--set"), "--set")
    return out


def profile_list(pipe: Pipeline, profile: str | None) -> list[str]:
    """The profiles ``profile`` names, in the order they apply: ``"paper,tiny"`` -> [paper, tiny];
    None -> [default_profile] (or none). Raises PipelineError naming an unknown one."""
    text = profile if profile is not None else (pipe.default_profile or "")
    names = [n.strip() for n in text.split(",") if n.strip()]
    for name in names:
        if name not in pipe.profiles:
            raise PipelineError(
                f"{pipe.path.name}: unknown profile '{name}'; fix: use one of: "
                f"{', '.join(pipe.profiles) or '(none defined)'}{suggest(name, pipe.profiles)}"
            )
    return names


def profile_device(pipe: Pipeline, profile: str | None) -> str | None:
    """The device the last profile of ``profile`` that names one asks for (None: none does)."""
    asked = [pipe.profile_devices[n] for n in profile_list(pipe, profile) if n in pipe.profile_devices]
    return asked[-1] if asked else None


def _apply(r: Resolved, key: str, value: Any, origin: str) -> None:
    if key == "engine":
        r.engine = value
    elif key == "resources":
        r.resources = r.resources.replace(**value)
    else:
        r.params[key] = value
    r.overrides[key] = origin

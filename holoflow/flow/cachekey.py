"""Cache keys: what determines a step's result, hashed; and why two keys differ, in words.

key = sha256(canonical JSON of {stage, code, engine, params, inputs, seed[, prompt]}) where
- ``code`` maps each source file to its digest: the stage program, every project file it imports
  (its import closure, holoflow/flow/code_closure.py), and the files under the stage's ``code:`` paths; named
  relative to pipeline.yaml's folder (a file outside it: relative to its search root, e.g.
  holoflow/stage.py). A ``.py`` file is hashed through its AST, so comments and formatting do not
  invalidate the cache; other files by their bytes. Digests and import lists are cached by
  (path, size, mtime_ns) in the store's cache/code.json, so an unchanged tree costs one stat per file.
- ``inputs`` maps each input name to {stage, tree}: tree = sha256 of the upstream step's output map
  (relative file name -> object digest). Downstream keys depend on upstream OUTPUT bytes, so a rerun
  that reproduces the same bytes leaves them unchanged (early cutoff).
- ``prompt`` is included only for stages declaring ``prompt: true``.
- Non-finite floats (``--set point_cloud.grad_threshold=.inf``) hash as ``{"float": "inf"}``,
  ``{"float": "-inf"}`` or ``{"float": "nan"}``; finite values hash as plain JSON numbers.
"""

from __future__ import annotations

import ast
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

from .code_closure import HOLOFLOW_ROOT, ImportGraph, parse_imports
from .store import canonical_json, sha256_bytes

_SKIP_DIRS = {"__pycache__", ".git", ".pytest_cache", ".mypy_cache", ".ipynb_checkpoints"}
_SKIP_SUFFIXES = {".pyc", ".pyo", ".swp", ".tmp"}


FORMAT_KEY, CACHE_FORMAT = "#format", 2  # code.json layout; 2: imports include entry-point strings


class CodeHasher:
    """Source digests and import lists cached by (size, mtime_ns); ``save()`` writes the cache back if
    it changed.

    Paths are handled as strings: this runs for every stage on every `status`, so it stays cheap.
    """

    def __init__(self, root: Path, cache_file: Path | None):
        self.root = str(root).rstrip("/") + "/"
        self.cache_file = cache_file
        self._cache: dict[str, list] = {}
        self._dirty = False
        self._walked: dict[str, list[tuple[str, str]]] = {}  # path -> [(absolute, relative)]
        self._seen: dict[str, list] = {}
        self._graphs: dict[str, ImportGraph] = {}  # program folder -> its import graph
        if cache_file is not None:
            try:
                self._cache = json.loads(cache_file.read_text())
            except (OSError, ValueError):
                self._cache = {}
            if self._cache.get(FORMAT_KEY) != CACHE_FORMAT:  # entries of an older parser: drop them
                self._cache = {FORMAT_KEY: CACHE_FORMAT}

    def version(self, paths: list[Path]) -> dict[str, str]:
        """{path relative to the root: digest} over every source file under ``paths``."""
        out = {}
        for p in map(str, paths):
            if p not in self._walked:
                self._walked[p] = [(f, self._relative(f, None)) for f in _walk(p)]
            for f, rel in self._walked[p]:
                out[rel] = self.digest(f)
        return out

    def closure(self, program: Path) -> dict[str, str]:
        """{name: digest} of ``program`` and every project file it imports (holoflow/flow/code_closure.py)."""
        prog = str(program)
        out = {self._relative(prog, None): self.digest(prog)}
        if not prog.endswith(".py"):
            return out
        for f, root in self._graph(prog).closure(prog).items():
            out[self._relative(f, root)] = self.digest(f)
        return out

    def files(self, program: Path) -> dict[str, str]:
        """{file: search root} of every project file ``program`` imports (absolute paths; empty for a
        non-Python program)."""
        prog = str(program)
        return self._graph(prog).closure(prog) if prog.endswith(".py") else {}

    def external(self, program: Path) -> set[str]:
        """Modules outside the project that ``program``'s closure imports (empty for a non-Python one)."""
        prog = str(program)
        return self._graph(prog).external(prog) if prog.endswith(".py") else set()

    def _graph(self, prog: str) -> ImportGraph:
        folder = os.path.dirname(prog)
        if folder not in self._graphs:
            roots = [(folder, None), (self.root.rstrip("/"), None), (HOLOFLOW_ROOT, frozenset({"holoflow"}))]
            self._graphs[folder] = ImportGraph(roots, self.imports)
        return self._graphs[folder]

    def digest(self, path: str) -> str:
        """Digest of one source file: one stat per process, a rehash only when (size, mtime_ns) moved."""
        return self._entry(path)[2]

    def imports(self, path: str) -> tuple[list, bool]:
        """``parse_imports`` of one Python file, cached like its digest."""
        entry = self._entry(path)
        return entry[3], entry[4]

    def _entry(self, path: str) -> list:
        """[size, mtime_ns, digest] (+ [imports, lazy] for a .py file), from the cache when current."""
        if path in self._seen:
            return self._seen[path]
        st = os.stat(path)
        python = path.endswith(".py")
        hit = self._cache.get(path)
        if hit and hit[0] == st.st_size and hit[1] == st.st_mtime_ns and len(hit) == (5 if python else 3):
            entry = hit
        else:
            with open(path, "rb") as f:
                data = f.read()
            tree = _python_tree(data) if python else None
            entry = [st.st_size, st.st_mtime_ns, _digest(tree, data)]
            if python:
                entry += list(parse_imports(tree)) if tree is not None else [[], False]
            self._cache[path] = entry
            self._dirty = True
        self._seen[path] = entry
        return entry

    def _relative(self, path: str, root: str | None) -> str:
        """``path`` relative to the pipeline's folder, else to its search root, else absolute."""
        if path.startswith(self.root):
            return path[len(self.root) :]
        if root is not None:
            return os.path.relpath(path, root)
        return path

    def save(self) -> None:
        if self._dirty and self.cache_file is not None:
            from .store import write_atomic

            try:
                write_atomic(self.cache_file, json.dumps(self._cache))
            except OSError:
                pass  # a cache only; a read-only store still works
            self._dirty = False


def _walk(p: str) -> list[str]:
    """Source files under ``p`` (a file or a folder), sorted; caches, dot-files and bytecode skipped."""
    if not os.path.isdir(p):
        return [p] if os.path.exists(p) else []
    out = []
    for dirpath, dirnames, filenames in os.walk(p):
        dirnames[:] = sorted(d for d in dirnames if d not in _SKIP_DIRS and not d.startswith("."))
        out.extend(
            os.path.join(dirpath, f)
            for f in sorted(filenames)
            if not f.startswith(".") and os.path.splitext(f)[1] not in _SKIP_SUFFIXES
        )
    return out


def source_digest(suffix: str, data: bytes) -> str:
    """sha256 of a source file; for Python, of its AST (comments and layout do not count)."""
    return _digest(_python_tree(data) if suffix == ".py" else None, data)


def _python_tree(data: bytes) -> ast.Module | None:
    try:
        return ast.parse(data)
    except (SyntaxError, ValueError):
        return None


def _digest(tree: ast.Module | None, data: bytes) -> str:
    if tree is not None:
        return "ast:" + sha256_bytes(ast.dump(tree, annotate_fields=False).encode())
    return sha256_bytes(data)


def tree_digest(outputs: dict[str, dict]) -> str:
    """One digest for a step's output map {relative name: {digest, ...}}."""
    return sha256_bytes(canonical_json({k: v["digest"] for k, v in outputs.items()}).encode())


def components(
    stage: str,
    code: dict[str, str],
    engine: str,
    params: dict[str, Any],
    inputs: dict[str, dict[str, str]],
    seed: int,
    prompt: str | None,
) -> dict[str, Any]:
    comp = {"stage": stage, "code": code, "engine": engine, "params": params, "inputs": inputs, "seed": seed}
    if prompt is not None:
        comp["prompt"] = prompt
    return comp


def cache_key(comp: dict[str, Any]) -> str:
    return hashlib.sha256(canonical_json(finite_json(comp)).encode()).hexdigest()


def finite_json(value: Any) -> Any:
    """``value`` with every non-finite float replaced by its tag {"float": "inf" | "-inf" | "nan"}."""
    if isinstance(value, float) and not math.isfinite(value):
        return {"float": "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")}
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(v) for v in value]
    return value


def reasons(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """Why ``new`` components differ from ``old``, in the user's words."""
    out = []
    if old.get("engine") != new.get("engine"):
        out.append(f"engine changed: {old.get('engine')} -> {new.get('engine')}")
    op, np_ = old.get("params", {}), new.get("params", {})
    for k in sorted(set(op) | set(np_)):
        if finite_json(op.get(k, "<unset>")) != finite_json(np_.get(k, "<unset>")):
            out.append(
                f"params changed: {new['stage']}.{k} {_short(op.get(k, '<unset>'))} -> {_short(np_.get(k, '<unset>'))}"
            )
    oc, nc = old.get("code", {}), new.get("code", {})
    changed = sorted(f for f in set(oc) | set(nc) if oc.get(f) != nc.get(f))
    if changed:
        more = f" (+{len(changed) - 3} more)" if len(changed) > 3 else ""
        out.append(f"code changed: {', '.join(changed[:3])}{more}")
    oi, ni = old.get("inputs", {}), new.get("inputs", {})
    for k in sorted(set(oi) | set(ni)):
        if oi.get(k) != ni.get(k):
            out.append(f"input changed: {(ni.get(k) or oi.get(k) or {}).get('stage', k)}")
    if old.get("seed") != new.get("seed"):
        out.append(f"seed changed: {old.get('seed')} -> {new.get('seed')}")
    if old.get("prompt") != new.get("prompt"):
        out.append(f"prompt changed: {_short(old.get('prompt'))} -> {_short(new.get('prompt'))}")
    return out or ["key changed"]


def _short(v: Any) -> str:
    s = json.dumps(v) if not isinstance(v, (int, float)) or isinstance(v, bool) else repr(v)
    return s if len(s) <= 40 else s[:37] + "..."

"""The project's own files a Python program runs through its imports, found with ``ast`` (nothing is
imported, so this stays cheap and never loads torch).

A program's import closure is, transitively: ``import a.b`` (a and a.b), ``from a import b`` (a, and
a.b when b is a submodule), relative imports, imports inside functions or ``try`` blocks (not under
``if TYPE_CHECKING:``, which never runs), and the ``__init__.py`` of every package on the way. A
package whose ``__init__`` defines a module-level ``__getattr__`` (PEP 562 lazy names, e.g.
holoflow/scene) counts as importing all its direct submodules. Modules are looked up in the search roots in order, as
Python would for a script: the
program's folder, then the pipeline's folder, then the folder holding the ``holoflow`` package (for
``holoflow`` only). Standard-library and third-party modules are outside the roots and not followed;
names built at run time (``importlib.import_module(name)``) are not, except one form: a string literal
``"package.module:attribute"`` anywhere in a file (an entry-point reference, as the engine registries
of holoflow/flow/params.py hold) counts as ``import package.module``. Anything else loaded by name goes in
the stage's ``code:``.
"""

from __future__ import annotations

import ast
import os
import re
from dataclasses import dataclass
from typing import Callable

HOLOFLOW_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # holds holoflow/

ImportRecord = tuple[int, str, list[str]]  # (level, module, imported names); [] for `import m`
ENTRY_POINT = re.compile(r"^([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+):[A-Za-z_]\w*$")  # "pkg.mod:attr"


def parse_imports(tree: ast.Module) -> tuple[list[ImportRecord], bool]:
    """(every import statement of the file, anywhere in it but under ``if TYPE_CHECKING:``; whether it
    defines a module-level __getattr__)."""
    records: list[ImportRecord] = []
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Import):
            records.extend((0, alias.name, []) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            records.append((node.level, node.module or "", [alias.name for alias in node.names]))
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and (m := ENTRY_POINT.match(node.value)):
            records.append((0, m.group(1), []))
        elif isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(reversed(node.orelse))  # the body never runs
            continue
        stack.extend(reversed(list(ast.iter_child_nodes(node))))
    lazy = any(isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == "__getattr__" for n in tree.body)
    return records, lazy


@dataclass(frozen=True)
class Found:
    """Where a module lives: its file ("" for a namespace package), search root, and package folder."""

    file: str
    root: str
    package_dir: str | None  # the folder of a package; None for a plain module


class ImportGraph:
    """Module lookup and import following over fixed search roots; memoised for the process.

    ``roots``: [(folder, top-level names it may provide, or None for any)]. ``parsed(file)`` returns
    the file's ``parse_imports`` result (the caller caches it across processes).
    """

    def __init__(
        self, roots: list[tuple[str, frozenset[str] | None]], parsed: Callable[[str], tuple[list[ImportRecord], bool]]
    ):
        self.roots = roots
        self.parsed = parsed
        self._listing: dict[str, frozenset[str]] = {}
        self._found: dict[str, Found | None] = {}
        self._deps: dict[str, list[str]] = {}

    def closure(self, program: str) -> dict[str, str]:
        """{file: search root} of every project file ``program`` imports, transitively (not itself)."""
        records, _ = self.parsed(program)
        stack = _targets(records, package="")
        seen: set[str] = set()
        files: dict[str, str] = {}
        while stack:
            module = stack.pop()
            if module in seen:
                continue
            seen.add(module)
            parent = module.rpartition(".")[0]
            if parent:
                stack.append(parent)  # importing a.b runs a/__init__.py first
            found = self.find(module)
            if found is None:
                continue
            if found.file:
                files[found.file] = found.root
            stack.extend(self.deps(module))
        files.pop(program, None)
        return files

    def external(self, program: str) -> set[str]:
        """Absolute names of the modules outside the project (third-party or standard library) that
        ``program`` or any file of its closure imports."""
        out: set[str] = set()
        for file in [program, *self.closure(program)]:
            for level, module, _ in self.parsed(file)[0]:
                if not level and module and self.find(module.partition(".")[0]) is None:
                    out.add(module)
        return out

    def find(self, module: str) -> Found | None:
        """Where ``module`` (dotted name) lives under the roots, or None when outside the project."""
        if module in self._found:
            return self._found[module]
        parent, _, leaf = module.rpartition(".")
        if not parent:
            hit = None
            for root, names in self.roots:
                here = self._find_in(root, root, leaf) if names is None or leaf in names else None
                if here is not None and here.file:
                    hit = here
                    break
                hit = hit or here  # a namespace folder yields to a later real module
        else:
            up = self.find(parent)
            hit = self._find_in(up.package_dir, up.root, leaf) if up and up.package_dir else None
        self._found[module] = hit
        return hit

    def deps(self, module: str) -> list[str]:
        """The modules ``module``'s file names in its imports (absolute; maybe outside the project)."""
        if module not in self._deps:
            found = self.find(module)
            out: list[str] = []
            if found is not None and found.file:
                records, lazy = self.parsed(found.file)
                out = _targets(records, module if found.package_dir else module.rpartition(".")[0])
                if lazy and found.package_dir:
                    out += [f"{module}.{name}" for name in _submodules(found.package_dir)]
            self._deps[module] = out
        return self._deps[module]

    def _find_in(self, folder: str, root: str, name: str) -> Found | None:
        if folder not in self._listing:
            try:
                self._listing[folder] = frozenset(os.listdir(folder))
            except OSError:
                self._listing[folder] = frozenset()
        names = self._listing[folder]
        path = os.path.join(folder, name)
        if name in names and os.path.isdir(path):
            init = os.path.join(path, "__init__.py")
            if os.path.isfile(init):
                return Found(init, root, path)
            if name + ".py" not in names:
                return Found("", root, path)
        if name + ".py" in names:
            return Found(path + ".py", root, None)
        return None


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _targets(records: list[ImportRecord], package: str) -> list[str]:
    """Absolute module names an import list may load; ``package``: the importing module's package."""
    out = []
    for level, module, names in records:
        if level:
            base = package.split(".") if package else []
            if not package or level - 1 >= len(base):
                continue  # beyond the top level: Python raises; nothing runs
            module = ".".join(base[: len(base) - level + 1] + ([module] if module else []))
        if not module:
            continue
        out.append(module)
        out.extend(f"{module}.{n}" for n in names if n != "*")
    return out


def _submodules(package_dir: str) -> list[str]:
    out = []
    for entry in sorted(os.listdir(package_dir)):
        if entry.endswith(".py") and entry != "__init__.py":
            out.append(entry[:-3])
        elif os.path.isfile(os.path.join(package_dir, entry, "__init__.py")):
            out.append(entry)
    return out

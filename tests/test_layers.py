"""The package's shape: no import cycle between any two files of holoflow/, the workflow core
(holoflow/flow) imports no domain package, the commands sit on top, only the public faces stay at the
package root, and the command-line path stays light."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import holoflow

PACKAGE = Path(holoflow.__file__).parent
ROOT_MODULES = {"__init__", "__main__", "stage"}  # the public faces: the package, `python -m`, stage programs
# flow reads and writes files through io (file formats), which decodes 8-bit images with the colour module;
# both are leaves: they import nothing else of holoflow
FLOW_MAY_IMPORT = {"holoflow", "holoflow.flow", "holoflow.stage", "holoflow.io", "holoflow.imageops.color"}
LEAVES = {"holoflow.io": {"holoflow.io", "holoflow.imageops.color"}, "holoflow.imageops.color": set()}


def _modules() -> dict[str, Path]:
    """{dotted module name: file} of every .py file of the package."""
    out = {}
    for f in sorted(PACKAGE.rglob("*.py")):
        parts = f.relative_to(PACKAGE.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def _imports(name: str, file: Path, modules: dict[str, Path]) -> set[str]:
    """Project modules ``file`` imports anywhere in it (functions and ``if TYPE_CHECKING:`` included): for
    ``from a import b`` the module a.b when it is one, else a. Parent packages are not counted: Python
    runs a package's __init__ before its submodules, which is no cycle of ours."""
    package = name if file.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(file.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        out.update(t for t in targets if t in modules and t != name)
    return out


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, f, modules) for name, f in modules.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_between_files():
    assert _cycles(_graph()) == []


def _within(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def test_flow_imports_no_domain_package():
    wrong = {
        (m, d)
        for m, deps in _graph().items()
        if _within(m, ["holoflow.flow"])
        for d in deps
        if not (d == "holoflow" or _within(d, FLOW_MAY_IMPORT - {"holoflow"}))
    }
    assert not wrong, sorted(wrong)


@pytest.mark.parametrize("leaf", sorted(LEAVES))
def test_what_flow_reads_through_is_a_leaf(leaf):
    wrong = {
        (m, d)
        for m, deps in _graph().items()
        if _within(m, [leaf])
        for d in deps
        if not _within(d, LEAVES[leaf] | {leaf})
    }
    assert not wrong, sorted(wrong)


def test_nothing_below_imports_the_commands():
    wrong = {
        (m, d)
        for m, deps in _graph().items()
        if not m.startswith(("holoflow.commands", "holoflow.__main__"))
        for d in deps
        if d.startswith("holoflow.commands")
    }
    assert not wrong, sorted(wrong)


TOOLS = ["holoflow.bench", "holoflow.commands", "holoflow.evaluation", "holoflow.report"]
DOMAIN = [
    "holoflow.scene",
    "holoflow.imageops",
    "holoflow.depth",
    "holoflow.geometry",
    "holoflow.splat",
    "holoflow.recon",
    "holoflow.export",
    "holoflow.networks",
    "holoflow.quality",
    "holoflow.io",
]


def test_no_domain_package_imports_a_tool_package():
    wrong = {(m, d) for m, deps in _graph().items() if _within(m, DOMAIN) for d in deps if _within(d, TOOLS)}
    assert not wrong, sorted(wrong)


def test_only_the_public_faces_at_the_package_root():
    assert {f.stem for f in PACKAGE.glob("*.py")} == ROOT_MODULES


@pytest.mark.parametrize(
    "module",
    [
        "holoflow.commands",
        "holoflow.commands.run",
        "holoflow.commands.status",
        "holoflow.flow.batch",
        "holoflow.flow.scheduler",
        "holoflow.flow.status",
    ],
)
def test_each_imports_alone_without_heavy_modules(module):
    code = (
        f"import sys, {module}; heavy = {{'torch', 'numpy', 'viser'}} & {{m.split('.')[0] for m in sys.modules}}; "
        f"assert not heavy, heavy"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_status_imports_nothing_heavy(project, capsys):
    project.run_json("p", capsys=capsys)
    r = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "holoflow", "status"],
        cwd=project.root,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and "fresh" in r.stdout, r.stderr
    imported = {
        line.split("|")[-1].strip().split(".")[0] for line in r.stderr.splitlines() if line.startswith("import time:")
    }
    assert not imported & {"torch", "numpy", "viser", "subprocess", "threading"}

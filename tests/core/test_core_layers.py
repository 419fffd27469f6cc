"""Orchestration modules import in one direction (no cycles), each alone, and `status` stays light."""
import subprocess
import sys

import pytest

from holoflow.cachekey import CodeHasher
from holoflow.imports import HOLOFLOW_ROOT, ImportGraph

ORCHESTRATION = ["holoflow.cli", "holoflow.batch", "holoflow.runner", "holoflow.status", "holoflow.summary",
                 "holoflow.cachekey", "holoflow.imports", "holoflow.pipeline", "holoflow.store",
                 "holoflow.progress"]


def _reachable(graph: ImportGraph, module: str) -> set[str]:
    """Project modules ``module`` imports, transitively (function-level imports included)."""
    seen: set[str] = set()
    stack = list(graph.deps(module))
    while stack:
        m = stack.pop()
        if m not in seen and graph.find(m) is not None:
            seen.add(m)
            stack.extend(graph.deps(m))
    return seen


@pytest.mark.parametrize("module", ORCHESTRATION)
def test_no_orchestration_module_imports_itself_back(module):
    graph = ImportGraph([(HOLOFLOW_ROOT, frozenset({"holoflow"}))], CodeHasher(HOLOFLOW_ROOT, None).imports)
    assert graph.find(module) is not None
    assert module not in _reachable(graph, module)


def test_batch_does_not_import_the_cli():
    graph = ImportGraph([(HOLOFLOW_ROOT, frozenset({"holoflow"}))], CodeHasher(HOLOFLOW_ROOT, None).imports)
    assert "holoflow.cli" not in _reachable(graph, "holoflow.batch")


@pytest.mark.parametrize("module", ["holoflow.cli", "holoflow.batch", "holoflow.runner", "holoflow.status"])
def test_each_imports_alone_without_heavy_modules(module):
    code = (f"import sys, {module}; heavy = {{'torch', 'numpy', 'viser'}} & {{m.split('.')[0] for m in sys.modules}}; "
            f"assert not heavy, heavy")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_status_imports_nothing_heavy(project, capsys):
    project.run_json("p", capsys=capsys)
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "holoflow", "status"], cwd=project.root,
                       capture_output=True, text=True)
    assert r.returncode == 0 and "fresh" in r.stdout, r.stderr
    imported = {line.split("|")[-1].strip().split(".")[0] for line in r.stderr.splitlines()
                if line.startswith("import time:")}
    assert not imported & {"torch", "numpy", "viser", "subprocess", "threading"}

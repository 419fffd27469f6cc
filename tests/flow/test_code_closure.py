"""The code part of a cache key is the step program's import closure inside the project."""

import shutil
from pathlib import Path

import pytest

from holoflow.flow import pipeline
from holoflow.flow.cachekey import CodeHasher, reasons
from holoflow.flow.context import Context, Options
from holoflow.flow.store import Store

ROOT = Path(__file__).resolve().parents[2]


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def _closure(root: Path, program: str) -> set[str]:
    return set(CodeHasher(root, None).closure(root / program))


def test_closure_follows_every_import_form(tmp_path):
    _write(
        tmp_path,
        {
            "prog.py": "import pkg.mod\nfrom pkg import sub\nif TYPE_CHECKING:\n    import other\n\n"
            "def main():\n    from lazy import thing\n",
            "pkg/__init__.py": "",
            "pkg/mod.py": "from . import rel\nfrom .deep.leaf import f\nimport numpy\n",
            "pkg/rel.py": "X = 1\n",
            "pkg/deep/__init__.py": "",
            "pkg/deep/leaf.py": "from .. import mod\n\ndef f():\n    pass\n",
            "pkg/sub.py": "",
            "pkg/unused.py": "",
            "lazy/__init__.py": (
                "def __getattr__(name):\n    import importlib\n    return importlib.import_module(name)\n"
            ),
            "lazy/a.py": "",
            "lazy/b/__init__.py": "",
            "other.py": "",
        },
    )
    assert _closure(tmp_path, "prog.py") == {
        "prog.py",
        "pkg/__init__.py",
        "pkg/mod.py",
        "pkg/rel.py",
        "pkg/deep/__init__.py",
        "pkg/deep/leaf.py",
        "pkg/sub.py",
        "lazy/__init__.py",
        "lazy/a.py",
        "lazy/b/__init__.py",
    }


def test_closure_terminates_on_a_cycle_and_reads_namespace_folders(tmp_path):
    _write(
        tmp_path,
        {
            "prog.py": "from tools import a\n",
            "tools/a.py": "from . import b\n",  # tools/ has no __init__.py: a namespace package
            "tools/b.py": "from tools import a\nimport tools.b\n",
        },
    )
    assert _closure(tmp_path, "prog.py") == {"prog.py", "tools/a.py", "tools/b.py"}


STAGE_CHECK = {"holoflow/io/__init__.py", "holoflow/io/validate.py", "holoflow/io/exr.py"}


def test_holoflow_is_found_outside_the_pipeline_folder(tmp_path):
    _write(tmp_path, {"prog.py": "def main():\n    from holoflow.stage import Job\n"})
    # holoflow/stage.py checks every step's outputs with holoflow/io/validate.py (which reads EXRs)
    assert _closure(tmp_path, "prog.py") == {"prog.py", "holoflow/__init__.py", "holoflow/stage.py", *STAGE_CHECK}


@pytest.fixture(scope="module")
def real_tree(tmp_path_factory):
    """A copy of the real pipeline, its stages and the holoflow package, to edit freely."""
    root = tmp_path_factory.mktemp("real")
    skip = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(ROOT / "holoflow", root / "holoflow", ignore=skip)
    shutil.copytree(ROOT / "stages", root / "stages", ignore=skip)
    shutil.copy(ROOT / "pipeline.yaml", root / "pipeline.yaml")
    return root


def _components(root: Path) -> dict[str, dict]:
    """Every stage's key components as a fresh `holoflow status` would compute them."""
    pipe = pipeline.load(root / "pipeline.yaml")
    ctx = Context.build(pipe, Store(root / "artifacts"), Options(prompt="a cabin"))
    outputs = {name: {} for name in pipe.stages}
    return {name: ctx.components(name, outputs) for name in pipe.stages}


def _edit(path: Path, extra: str) -> str:
    before = path.read_text()
    path.write_text(before + extra)
    return before


@pytest.mark.parametrize(
    "module, stale",
    [
        ("holoflow/quality/metrics.py", {"pre_opt", "inp_set", "transfer_opt"}),
        ("holoflow/stage.py", "all"),
        ("holoflow/networks/zoedepth.py", {"tangent_depth", "metric_align"}),
        ("holoflow/bench/cache.py", set()),
    ],
)
def test_editing_an_imported_module_makes_exactly_its_importers_stale(real_tree, module, stale):
    before = _components(real_tree)
    path = real_tree / module
    text = _edit(path, "# a comment only\n")
    try:
        assert _components(real_tree) == before
        path.write_text(text + "\n_EDITED = 1\n")
        after = _components(real_tree)
    finally:
        path.write_text(text)
    changed = {n for n in before if after[n] != before[n]}
    assert changed == (set(before) if stale == "all" else stale)
    for name in changed:
        assert reasons(before[name], after[name]) == [f"code changed: {module}"]


def test_status_names_a_function_level_import(project, capsys):
    _write(project.root, {"tools/a.py": "from . import b\n", "tools/b.py": "from tools import a\nY = 1\n"})
    _edit(project.root / "upper.py", "\n\ndef _late():\n    from tools import a\n")
    project.run_json("p", capsys=capsys)
    _edit(project.root / "tools" / "b.py", "Y = 2\n")
    rc, out, _ = project.cli("status", capsys=capsys)
    lines = dict(line.split(None, 1) for line in out.splitlines())
    assert lines["upper"].split(None, 1) == ["stale", "code changed: tools/b.py"]
    assert lines["gen"].startswith("fresh")
    assert lines["join"] == "stale    upstream not fresh: upper"


def test_entry_point_strings_count_as_imports(tmp_path):
    _write(
        tmp_path,
        {
            "prog.py": "from reg import ENGINES\n",
            "reg.py": 'ENGINES = {"fast": "impl.fast:run", "doc": "not an import: a.b c"}\n',
            "impl/__init__.py": "",
            "impl/fast.py": "def run(): pass\n",
        },
    )
    assert _closure(tmp_path, "prog.py") == {"prog.py", "reg.py", "impl/__init__.py", "impl/fast.py"}

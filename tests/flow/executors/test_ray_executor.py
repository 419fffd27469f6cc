"""The Ray executor on a local 2-CPU Ray cluster (one per module): a batch of 3 tiny scenes gives the
same bytes as the local executor; a killed step and a lost worker are retried; several workers that
finish the same key at once leave one record and intact objects."""

import hashlib
import json
import os
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from holoflow.commands import main  # noqa: E402
from holoflow.flow.executors import StepTask  # noqa: E402
from holoflow.flow.store import Store  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]

# First attempt: kill itself (a step killed on a worker) or its parent (the Ray worker: a lost worker).
KILL_ONCE = """import os, signal
from pathlib import Path
from holoflow.stage import Job
job = Job.from_argv()
marker = Path(job.params["marker"])
if not marker.exists():
    marker.write_text("1")
    os.kill(os.getppid() if job.params["victim"] == "parent" else os.getpid(), signal.SIGKILL)
job.output("out.txt").write_text(job.stage + " " + job.prompt + "\\n")
"""
COPY = """from holoflow.stage import Job
job = Job.from_argv()
job.output("out.txt").write_bytes(job.input_file("src", "out.txt").read_bytes() * 2)
"""


@pytest.fixture(scope="module")
def cluster():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


def _cli(capsys, *args):
    rc = main(list(args))
    out, err = capsys.readouterr()
    assert rc == 0, err
    return json.loads(out[out.index("{\n") :])  # (a late Ray notice may precede the JSON)


def _consistent(root: Path) -> None:
    for obj in Store(root).iter_objects():
        assert hashlib.sha256(obj.read_bytes()).hexdigest() == obj.name
    for rec_path in (root / "keys").glob("*.json"):
        for e in json.loads(rec_path.read_text())["outputs"].values():
            assert Store(root).object_path(e["digest"]).is_file()


def test_tiny_batch_on_ray_equals_local(cluster, tmp_path, capsys):
    prompts = tmp_path / "p.txt"
    prompts.write_text("a small wooden cabin\na foggy forest at dawn\na red brick room\n")
    args = [
        "run",
        "--pipeline",
        str(ROOT / "pipeline.yaml"),
        "--prompts",
        str(prompts),
        "--profile",
        "tiny",
        "--until",
        "detail",
        "--json",
    ]
    local = _cli(capsys, *args, "--store", str(tmp_path / "local"), "-j", "2")
    remote = _cli(capsys, *args, "--store", str(tmp_path / "ray"), "--executor", "ray")
    assert remote["executor"].startswith("ray") and len(remote["scenes"]) == 3
    digests = [[{n: s["outputs"] for n, s in sc["stages"].items()} for sc in b["scenes"]] for b in (local, remote)]
    assert digests[0] == digests[1]
    assert len({json.dumps(d, sort_keys=True) for d in digests[1]}) == 3  # three different scenes
    store = Store(tmp_path / "ray")
    rec = store.record(remote["scenes"][0]["stages"]["detail"]["key"])
    assert rec["provenance"]["executor"] == "ray" and rec["provenance"]["host"] == os.uname().nodename
    assert rec["provenance"]["resources"]["cpus"] == 1
    _consistent(store.root)


def test_killed_step_and_lost_worker_are_retried(cluster, tmp_path, capsys):
    (tmp_path / "kill_once.py").write_text(KILL_ONCE)
    (tmp_path / "twice.py").write_text(COPY)
    (tmp_path / "pipeline.yaml").write_text(f"""version: 1
stages:
  first: {{run: kill_once.py, prompt: true, params: {{marker: "{tmp_path / "m1"}", victim: self}}}}
  second: {{run: kill_once.py, prompt: true, params: {{marker: "{tmp_path / "m2"}", victim: parent}}}}
  third: {{run: twice.py, inputs: {{src: first}}}}
""")
    s = _cli(capsys, "run", "p", "--pipeline", str(tmp_path / "pipeline.yaml"), "--executor", "ray", "--json")
    assert {n: st["how"] for n, st in s["stages"].items()} == {"first": "ran", "second": "ran", "third": "ran"}
    store = Store(tmp_path / "artifacts")
    for stage in ("first", "second"):
        assert store.record(s["stages"][stage]["key"])["provenance"]["attempt"] == 2
    _consistent(store.root)
    assert (tmp_path / "artifacts" / "latest" / "third" / "out.txt").read_text() == "first p\nfirst p\n"


def test_same_key_committed_by_several_workers(cluster, tmp_path):
    from holoflow.flow.executors.ray_executor import _ray_step

    (tmp_path / "twice.py").write_text(
        "from holoflow.stage import Job\nJob.from_argv().output('o.bin').write_bytes(bytes(range(256)) * 4096)\n"
    )
    store = Store(tmp_path / "s")
    store.ensure()
    task = StepTask(
        store=str(store.root),
        stage="c",
        label="c",
        key="f" * 64,
        components={},
        spec={"stage": "c", "engine": "default", "run": "r"},
        program=str(tmp_path / "twice.py"),
        cwd=str(tmp_path),
        resources={"cpus": 1},
        provenance={},
    )
    remote = ray.remote(_ray_step)
    results = ray.get([remote.options(num_cpus=0.5).remote(task) for _ in range(4)])
    assert all(r["ok"] for r in results), results
    recs = [r["record"] for r in results]
    assert all(r == store.record("f" * 64) for r in recs)  # the first commit won everywhere
    assert [p.name for p in store.iter_objects()] == sorted(
        {recs[0]["outputs"]["o.bin"]["digest"], recs[0]["provenance"]["log"]}
    )
    _consistent(store.root)
    assert list((store.root / "tmp").iterdir()) == []

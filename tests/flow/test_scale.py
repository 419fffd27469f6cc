"""Scale-out on one machine: -j N concurrency and resource slots, batches (--prompts, sweep), shared
steps, per-step retries, first-wins concurrent commits, non-finite params in cache keys."""

import hashlib
import json
import math
import os
import threading
import time
from pathlib import Path

import pytest

from holoflow.commands import main
from holoflow.flow import pipeline
from holoflow.flow.cachekey import cache_key, components
from holoflow.flow.store import Store

# A stage that proves (or refutes) that it ran at the same time as its peers: it registers in a
# folder, then either waits for a second registration ("together") or checks none is there ("alone").
SLOT = """import os, sys, time
from pathlib import Path
from holoflow.stage import Job
job = Job.from_argv()
peers = Path(job.params["peers"])
me = peers / job.stage
me.write_text(os.environ.get("CUDA_VISIBLE_DEVICES", "-"))
if job.params["want"] == "together":      # registrations stay: a peer that finished still counts
    deadline = time.monotonic() + 15
    while len(list(peers.iterdir())) < 2 and time.monotonic() < deadline:
        time.sleep(0.02)
    ok = len(list(peers.iterdir())) >= 2
else:
    time.sleep(0.4)
    ok = [p.name for p in peers.iterdir()] == [job.stage]
    me.unlink()
if not ok:
    sys.exit("slot: peers " + job.params["want"] + " expected")
job.output("out.txt").write_text(job.stage + " " + os.environ.get("OMP_NUM_THREADS", "?") + "\\n")
"""

# Kills itself (SIGKILL) on its first attempt: a marker file remembers the attempt.
KILL_ONCE = """import os, signal
from pathlib import Path
from holoflow.stage import Job
job = Job.from_argv()
marker = Path(job.params["marker"])
if not marker.exists():
    marker.write_text("1")
    os.kill(os.getpid(), signal.SIGKILL)
job.output("out.txt").write_text("survived\\n")
"""


def _toy(root: Path, stages: str) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    (root / "slot.py").write_text(SLOT)
    (root / "kill_once.py").write_text(KILL_ONCE)
    (root / "pipeline.yaml").write_text("version: 1\nstages:\n" + stages)
    return root / "pipeline.yaml"


def _cli(capsys, *args):
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def _digests(batch):
    return [{n: s["outputs"] for n, s in sc["stages"].items()} for sc in batch["scenes"]]


def test_j2_runs_independent_steps_together(tmp_path, capsys):
    peers = tmp_path / "peers"
    peers.mkdir()
    pipe = _toy(
        tmp_path / "p",
        f"""
  a: {{run: slot.py, params: {{peers: "{peers}", want: together}}}}
  b: {{run: slot.py, params: {{peers: "{peers}", want: together}}}}
""",
    )
    rc, out, err = _cli(capsys, "run", "--pipeline", str(pipe), "-j", "2", "--json")
    assert rc == 0, err
    for p in peers.iterdir():
        p.unlink()
    rc, out, err = _cli(
        capsys, "run", "--pipeline", str(pipe), "--force", "all", "-j", "1", "--set", "a.peers=" + str(tmp_path)
    )
    assert rc == 1 and "slot: peers together expected" in err  # -j 1 really runs one at a time


def test_gpu_stages_never_share_a_gpu(tmp_path, capsys, monkeypatch):
    peers = tmp_path / "peers"
    peers.mkdir()
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3")  # one (pretend) GPU
    pipe = _toy(
        tmp_path / "p",
        f"""
  a: {{run: slot.py, params: {{peers: "{peers}", want: alone}}, resources: {{gpus: 1}}}}
  b: {{run: slot.py, params: {{peers: "{peers}", want: alone}}, resources: {{gpus: 1}}}}
  c: {{run: slot.py, params: {{peers: "{peers}", want: alone}}, resources: {{cpus: 4}}}}
""",
    )
    rc, out, err = _cli(capsys, "run", "--pipeline", str(pipe), "-j", "4", "--device", "cuda")
    assert rc == 0, err
    store = Store(tmp_path / "p" / "artifacts")
    rec = store.record(store.last_key("a"))
    assert rec["provenance"]["resources"] == {"cpus": 1, "gpus": 1, "memory_gb": 0.0, "gpu_ids": "3"}
    # cpus: 4 takes every slot of -j 4 (so c ran alone) and sets the step's thread count
    threads = min(4, os.cpu_count() or 1)
    assert (
        store.object_path(store.record(store.last_key("c"))["outputs"]["out.txt"]["digest"]).read_text()
        == f"c {threads}\n"
    )
    rc, out, _ = _cli(capsys, "status", "--pipeline", str(pipe))
    assert rc == 0 and "a  fresh    on " in out and "1 cpu, 1 gpu #3" in out


def test_batch_matches_single_runs_and_shares_steps(project, capsys, tmp_path):
    prompts = tmp_path / "p.yaml"
    prompts.write_text("- one\n- {prompt: one, set: {upper.mode: title}}\n- {prompt: two, seed: 3}\n")
    rc, out, err = project.cli("run", "--prompts", str(prompts), "-j", "2", "--json", capsys=capsys)
    assert rc == 0, err
    batch = json.loads(out)
    hows = [project.how(sc) for sc in batch["scenes"]]
    assert hows[0] == {"gen": "ran", "upper": "ran", "join": "ran"}
    assert hows[1] == {"gen": "cached", "upper": "ran", "join": "ran"}  # gen shared with s1
    assert batch["scenes"][2]["seed"] == 3 and hows[2]["gen"] == "ran"
    runs = [sc["run"] for sc in batch["scenes"]]
    assert len(set(runs)) == 3 and sorted(runs) == sorted(p.name for p in (project.store / "pins").iterdir())
    assert (project.store / "latest").resolve().name == runs[-1]
    # the same scenes one by one, sequentially, in a fresh store: byte-identical outputs
    singles = []
    for args in (["one"], ["one", "--set", "upper.mode=title"], ["two", "--seed", "3"]):
        singles.append(project.run_json(*args, "--store", str(tmp_path / "seq"), capsys=capsys))
    assert _digests(batch) == [{n: s["outputs"] for n, s in x["stages"].items()} for x in singles]


def test_prompts_text_file_and_sweep(project, capsys, tmp_path):
    prompts = tmp_path / "p.txt"
    prompts.write_text("# scenes\nalpha\n\nbeta\n")
    rc, out, err = project.cli("run", "--prompts", str(prompts), capsys=capsys)
    assert rc == 0, err
    assert "s1: 3 ran" in out and "s2: 3 ran" in out and '"beta"' in out
    rc, out, err = project.cli(
        "sweep", "alpha", "--grid", "upper.mode=upper,title", "--grid", "gen.n=2,3", "-j", "2", "--json", capsys=capsys
    )
    assert rc == 0, err
    scenes = json.loads(out)["scenes"]
    assert [sc["sets"] for sc in scenes] == [
        ["upper.mode=upper", "gen.n=2"],
        ["upper.mode=upper", "gen.n=3"],
        ["upper.mode=title", "gen.n=2"],
        ["upper.mode=title", "gen.n=3"],
    ]
    assert [sc["stages"]["gen"]["how"] for sc in scenes] == ["cached", "ran", "cached", "cached"]
    rc, out, err = project.cli("sweep", "alpha", "--grid", "upper.mode", capsys=capsys)
    assert rc == 2 and "expected STAGE.PARAM=V1,V2" in err


def test_prompts_file_mistakes_are_one_line(project, capsys, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("- {prompt: x, sets: {}}\n")
    rc, _, err = project.cli("run", "--prompts", str(bad), capsys=capsys)
    assert rc == 2 and "item 1 must be a prompt or a mapping" in err and len(err.strip().splitlines()) == 1
    bad.write_text("- {prompt: x, set: {upper.nope: 1}}\n")
    rc, _, err = project.cli("run", "--prompts", str(bad), capsys=capsys)
    assert rc == 2 and "scene s1:" in err and "unknown param 'nope'" in err


def test_killed_step_is_retried(tmp_path, capsys):
    pipe = _toy(
        tmp_path / "p",
        f"""
  k: {{run: kill_once.py, params: {{marker: "{tmp_path / "marker"}"}}}}
""",
    )
    rc, _, err = _cli(capsys, "run", "--pipeline", str(pipe))
    assert rc == 1 and "stage 'k' failed (killed by signal 9)" in err
    (tmp_path / "marker").unlink()
    rc, out, err = _cli(capsys, "run", "--pipeline", str(pipe), "--retries", "1")
    assert rc == 0 and "k: attempt 1 failed (killed by signal 9); retrying" in out
    store = Store(tmp_path / "p" / "artifacts")
    assert store.record(store.last_key("k"))["provenance"]["attempt"] == 2
    assert list((store.root / "tmp").iterdir()) == []


def test_concurrent_commits_of_one_key_first_wins(tmp_path):
    store = Store(tmp_path / "s")
    store.ensure()
    n = 8
    barrier = threading.Barrier(n)
    results = [None] * n

    def commit(i):
        src = store.staging(f"w{i}") / "f"
        src.write_bytes(b"same bytes" * 1000)
        barrier.wait()
        entry = store.put(src)
        results[i] = store.write_record(
            {"key": "k" * 64, "stage": "s", "outputs": {"f": entry}, "components": {}, "provenance": {"worker": i}},
            replace=False,
        )

    threads = [threading.Thread(target=commit, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    winner = store.record("k" * 64)
    assert all(r["provenance"] == winner["provenance"] for r in results)  # everyone adopted the first
    objs = list(store.iter_objects())
    assert len(objs) == 1 and hashlib.sha256(objs[0].read_bytes()).hexdigest() == objs[0].name
    assert not [p for p in (store.root / "keys").iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("text, value", [(".inf", math.inf), ("-.inf", -math.inf), (".nan", math.nan)])
def test_non_finite_params_hash_canonically(text, value):
    # a float param with no valid range (the toy pipeline's): the real stages' classes bound theirs
    p = pipeline.load(Path(__file__).resolve().parent / "fixtures" / "pipeline.yaml")
    got = pipeline.resolve(p, None, [f"upper.scale={text}"])["upper"].params["scale"]
    assert type(got) is float and (math.isnan(got) if math.isnan(value) else got == value)

    def key(v):
        return cache_key(components("point_cloud", {}, "default", {"grad_threshold": v}, {}, 0, None))

    assert key(got) == key(float(text.replace(".", "")))  # same value, same key (nan included)
    assert key(got) not in {key(0.4), key(text), key(-got if not math.isnan(got) else 0.0)}


def test_non_finite_params_of_the_real_stages_obey_their_ranges():
    p = pipeline.load(Path(__file__).resolve().parents[2] / "pipeline.yaml")
    got = pipeline.resolve(p, None, ["point_cloud.grad_threshold=.inf"])["point_cloud"].params["grad_threshold"]
    assert got == math.inf  # keep every point: a valid threshold
    for text in ("-.inf", ".nan"):
        with pytest.raises(pipeline.PipelineError, match="outside the valid range >= 0"):
            pipeline.resolve(p, None, [f"point_cloud.grad_threshold={text}"])


def test_inf_param_runs_and_stays_cached(project, capsys):
    s = project.run_json("p", "--set", "upper.scale=.inf", capsys=capsys)
    assert s["ok"] and project.how(s)["upper"] == "ran"
    s = project.run_json("--set", "upper.scale=.inf", capsys=capsys)
    assert set(project.how(s).values()) == {"cached"}
    rc, out, _ = project.cli("status", "--set", "upper.scale=-.inf", capsys=capsys)
    assert rc == 0 and "params changed: upper.scale inf -> -inf" in out


def test_resources_are_validated(tmp_path, capsys):
    pipe = _toy(tmp_path / "p", "  a: {run: slot.py, resources: {cpus: 0}}\n")
    rc, _, err = _cli(capsys, "status", "--pipeline", str(pipe))
    assert rc == 2 and "stage 'a': `resources:` sets cpus=0; fix: give cpus an integer >= 1" in err
    pipe = _toy(tmp_path / "p", "  a: {run: slot.py, resources: {gpu: 1}}\n")
    rc, _, err = _cli(capsys, "status", "--pipeline", str(pipe))
    assert rc == 2 and "unknown key 'gpu'" in err and "did you mean 'gpus'" in err
    pipe = _toy(tmp_path / "p", "  a: {run: slot.py, resources: 2}\n")
    rc, _, err = _cli(capsys, "status", "--pipeline", str(pipe))
    assert rc == 2 and "`resources:` is an integer, not a mapping" in err


def test_noop_parallel_run_stays_fast_and_light(project, capsys):
    import subprocess
    import sys

    project.run_json("p", "-j", "2", capsys=capsys)
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "holoflow", "run", "-j", "2"],
        cwd=project.root,
        capture_output=True,
        text=True,
    )
    wall = time.monotonic() - t0
    assert r.returncode == 0 and "3 cached" in r.stdout, r.stderr
    imported = {
        line.split("|")[-1].strip().split(".")[0] for line in r.stderr.splitlines() if line.startswith("import time:")
    }
    assert not imported & {"torch", "numpy", "ray", "subprocess", "threading"}
    assert wall < 2.0  # (0.5 s budget measured in docs/bench-cache.md; generous for -X importtime)

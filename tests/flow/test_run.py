"""Run, cache, early cutoff, --force, --set and back, selection flags, status reasons, failures."""

import json
import os
import stat


def test_run_then_cached_then_status(project, capsys):
    s = project.run_json("a cabin", capsys=capsys)
    assert project.how(s) == {"gen": "ran", "upper": "ran", "join": "ran"}
    link = project.store / "latest" / "upper" / "text.txt"
    assert link.read_text().startswith("A CABIN 0 SEED=7")
    assert not os.access(os.path.realpath(link), os.W_OK) or os.getuid() == 0
    assert stat.S_IMODE(os.stat(link).st_mode) == 0o444
    s2 = project.run_json(capsys=capsys)  # prompt defaults to the last run's
    assert project.how(s2) == {"gen": "cached", "upper": "cached", "join": "cached"}
    assert s2["run"] == s["run"]  # nothing changed: no new run
    rc, out, _ = project.cli("status", capsys=capsys)
    assert rc == 0 and all(line.split()[1] == "fresh" for line in out.strip().splitlines())


def test_record_has_provenance(project, capsys):
    s = project.run_json("p", capsys=capsys)
    rec = json.loads((project.store / "keys" / f"{s['stages']['gen']['key']}.json").read_text())
    prov = rec["provenance"]
    assert prov["exit_code"] == 0 and prov["seed"] == 7 and prov["engine"] == "basic"
    assert prov["meta"]["lines"] == 2 and prov["versions"]["torch"] == "not-used"
    assert prov["peak_rss_mb"] > 0 and prov["wall_s"] > 0
    log = (project.store / "objects" / prov["log"][:2] / prov["log"]).read_text()
    assert "@progress" in log
    # the program, what it imports (holoflow/stage.py and its package), and its `code:` folder
    assert rec["components"]["code"].keys() == {
        "gen.py",
        "holoflow/__init__.py",
        "holoflow/stage.py",
        "lib/helpers.py",
        "holoflow/io/__init__.py",
        "holoflow/io/validate.py",
        "holoflow/io/exr.py",
    }


def test_force_reruns_one_step_and_cutoff_keeps_downstream(project, capsys):
    project.run_json("p", capsys=capsys)
    s = project.run_json("--force", "upper", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "cut off"}


def test_set_reruns_dependents_and_setting_back_is_cached(project, capsys):
    project.run_json("p", capsys=capsys)
    s = project.run_json("--set", "upper.mode=title", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "ran"}
    s = project.run_json(capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "cached", "join": "cached"}
    # a float param set to an equal int value is the same key
    s = project.run_json("--set", "upper.scale=0.5", capsys=capsys)
    assert set(project.how(s).values()) == {"cached"}


def test_comment_edit_keeps_cache_code_edit_invalidates(project, capsys):
    project.run_json("p", capsys=capsys)
    helpers = project.root / "lib" / "helpers.py"
    helpers.write_text(helpers.read_text() + "# just a comment\n")
    assert set(project.how(project.run_json(capsys=capsys)).values()) == {"cached"}
    helpers.write_text(helpers.read_text() + "Y = 2\n")
    rc, out, _ = project.cli("status", capsys=capsys)
    assert "code changed: lib/helpers.py" in out
    assert project.how(project.run_json(capsys=capsys))["gen"] == "ran"


def test_status_reasons(project, capsys):
    project.run_json("p", capsys=capsys)
    rc, out, _ = project.cli("status", "--json", "--set", "upper.mode=title", capsys=capsys)
    st = json.loads(out)["stages"]
    assert st["gen"]["state"] == "fresh"
    assert st["upper"] == {
        "state": "stale",
        "key": st["upper"]["key"],
        "reasons": ['params changed: upper.mode "upper" -> "title"'],
    }
    assert st["join"]["state"] == "stale" and st["join"]["reasons"] == ["upstream not fresh: upper"]
    rc, out, _ = project.cli("status", "--profile", "big", capsys=capsys)
    assert "engine changed: basic -> fancy" in out and "params changed: gen.n 2 -> 5" in out
    rc, out, _ = project.cli("status", "another prompt", capsys=capsys)
    assert 'prompt changed: "p" -> "another prompt"' in out
    rc, out, _ = project.cli("status", "--seed", "8", capsys=capsys)
    assert "seed changed: 7 -> 8" in out
    # after a downstream-only change, the input is the reason
    project.run_json("--set", "upper.mode=title", "--until", "upper", capsys=capsys)
    rc, out, _ = project.cli("status", "--json", "--set", "upper.mode=title", capsys=capsys)
    st = json.loads(out)["stages"]
    assert st["join"]["reasons"] == ["input changed: upper"]


def test_selection_flags(project, capsys):
    s = project.run_json("p", "--until", "upper", capsys=capsys)
    assert project.how(s) == {"gen": "ran", "upper": "ran"}
    s = project.run_json("--only", "join", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "cached", "join": "ran"}
    s = project.run_json("--from", "upper", "--force", "upper", capsys=capsys)
    assert project.how(s) == {"gen": "cached", "upper": "ran", "join": "cut off"}
    rc, out, err = project.cli("run", "--only", "join", "--set", "gen.n=4", capsys=capsys)
    assert rc == 2 and "stage 'gen' is needed but has no cached result" in err
    assert "params changed: gen.n 2 -> 4" in err


def test_dry_run_runs_nothing(project, capsys):
    rc, out, _ = project.cli("run", "p", "--dry-run", capsys=capsys)
    assert rc == 0 and "gen" in out and not (project.store / "objects").exists()


def test_failed_step_commits_nothing_and_keeps_earlier(project, capsys):
    project.run_json("p", capsys=capsys)
    rc, out, err = project.cli("run", "--set", "gen.fail=true", capsys=capsys)
    assert rc == 1 and "stage 'gen' failed (exit code 3)" in err and "gen: failing on purpose" in err
    assert "last lines of" in err and "Traceback" not in err
    assert list((project.store / "tmp").iterdir()) == []
    # earlier results still served
    assert set(project.how(project.run_json(capsys=capsys)).values()) == {"cached"}


def test_non_python_program(project, capsys):
    (project.root / "pipeline.yaml").write_text(
        (project.root / "pipeline.yaml").read_text().replace("profiles:", "  shout:\n    run: shout.sh\nprofiles:")
    )
    s = project.run_json("p", capsys=capsys)
    assert s["stages"]["shout"]["how"] == "ran"
    assert (project.store / "latest" / "shout" / "hello.txt").read_text() == "hello\n"
    launch = {n: project.store_record(s, n)["provenance"]["launch"] for n in ("gen", "shout")}
    assert launch == {"gen": "warm", "shout": "cold"}  # a non-Python program is always exec'd


def test_cold_flag_and_env_exec_every_step(project, capsys, monkeypatch):
    s = project.run_json("p", "--cold", capsys=capsys)
    assert project.store_record(s, "gen")["provenance"]["launch"] == "cold"
    monkeypatch.setenv("HOLOFLOW_COLD", "1")
    s = project.run_json("--force", "all", capsys=capsys)
    assert {project.store_record(s, n)["provenance"]["launch"] for n in s["stages"]} == {"cold"}


def test_store_location(project, capsys, tmp_path, monkeypatch):
    other = tmp_path / "elsewhere"
    monkeypatch.setenv("HOLOFLOW_STORE", str(other))
    project.run_json("p", capsys=capsys)
    assert (other / "latest" / "join" / "joined.txt").exists() and not project.store.exists()
    s = project.run_json("p", "--store", str(tmp_path / "third"), capsys=capsys)
    assert set(project.how(s).values()) == {"ran"}


def test_cached_run_and_status_import_nothing_heavy(project, capsys):
    import subprocess
    import sys

    project.run_json("p", capsys=capsys)
    for cmd in (["run"], ["status"]):
        r = subprocess.run(
            [sys.executable, "-X", "importtime", "-m", "holoflow", *cmd],
            cwd=project.root,
            capture_output=True,
            text=True,
        )
        assert r.returncode == 0, r.stderr
        imported = {
            line.split("|")[-1].strip().split(".")[0]
            for line in r.stderr.splitlines()
            if line.startswith("import time:")
        }
        assert not imported & {"torch", "numpy", "rich", "OpenImageIO", "OpenEXR", "subprocess"}, cmd


def test_log_command(project, capsys):
    project.run_json("p", capsys=capsys)
    rc, out, _ = project.cli("log", "gen", capsys=capsys)
    assert rc == 0 and '@progress {"done": 2, "total": 2, "what": "lines"}' in out


def test_warm_templates_are_started_for_every_step_at_the_first_submit(project, capsys, monkeypatch):
    # templates start ahead of their steps so their imports overlap the steps before them
    from holoflow.flow.executors.local import LocalExecutor

    calls = []
    real = LocalExecutor.expect
    monkeypatch.setattr(
        LocalExecutor, "expect", lambda self, needs, ahead=(): (calls.append(needs), real(self, needs, ahead))[1]
    )
    project.run_json("p", capsys=capsys)
    assert len(calls) == 1 and len(calls[0]) == 3  # gen, upper, join: all known at the start


def test_an_engine_the_step_chose_is_named_by_run_and_status(project, capsys):
    rc, out, err = project.cli("run", "p", "--set", "gen.engine=fancy", capsys=capsys)
    assert rc == 0, err
    line = next(ln for ln in (out + err).splitlines() if "gen: ran" in ln)
    assert line.endswith("; engine fancy-v2 (fancy: the toy picks its v2)")
    assert not any("; engine" in ln for ln in (out + err).splitlines() if "upper: ran" in ln)  # chose nothing
    rc, out, _ = project.cli("status", "--set", "gen.engine=fancy", capsys=capsys)
    gen = next(ln for ln in out.splitlines() if ln.startswith("gen"))
    assert "engine fancy-v2 (fancy: the toy picks its v2)" in gen

"""User mistakes: each ends with one clear line naming the file/stage and the fix, exit code 2."""

import os
from pathlib import Path

import pytest
import yaml

FIXTURES = Path(__file__).parent / "fixtures"


def _mutate(fn):
    def apply(doc):
        fn(doc)
        return doc

    return apply


BROKEN = [  # (id, mutation of the parsed toy pipeline or raw text, expected words)
    ("not-yaml", "stages: [gen\n  : x", "not valid YAML at line"),
    ("top-list", "- a\n- b\n", "top level is a list"),
    ("unknown-top", _mutate(lambda d: d.update(stagse={})), "unknown top-level key 'stagse'"),
    ("bad-version", _mutate(lambda d: d.update(version=2)), "set `version: 1`"),
    ("seed-string", _mutate(lambda d: d.update(seed="x")), "set `seed:` to an integer"),
    ("no-stages", _mutate(lambda d: d.pop("stages")), "no `stages:` mapping"),
    ("stage-scalar", _mutate(lambda d: d["stages"].update(gen="gen.py")), "stage 'gen': block is a string"),
    (
        "unknown-stage-key",
        _mutate(lambda d: d["stages"]["upper"].update(parms={})),
        "stage 'upper': unknown key 'parms'",
    ),
    ("missing-run", _mutate(lambda d: d["stages"]["upper"].pop("run")), "stage 'upper': missing `run:`"),
    (
        "engine-not-listed",
        _mutate(lambda d: d["stages"]["gen"].update(engine="turbo")),
        "engine 'turbo' is not in engines",
    ),
    ("engines-not-list", _mutate(lambda d: d["stages"]["gen"].update(engines="basic")), "`engines:` is not a list"),
    (
        "input-unknown-stage",
        _mutate(lambda d: d["stages"]["upper"].update(inputs={"src": "gne"})),
        "input 'src' names unknown stage 'gne'; fix: name one of: gen, upper, join (did you mean 'gen'?)",
    ),
    ("input-self", _mutate(lambda d: d["stages"]["upper"].update(inputs={"src": "upper"})), "names the stage itself"),
    ("cycle", _mutate(lambda d: d["stages"]["gen"].update(inputs={"x": "join"})), "inputs form a cycle"),
    ("inputs-list", _mutate(lambda d: d["stages"]["upper"].update(inputs=["gen"])), "`inputs:` is not a mapping"),
    ("prompt-string", _mutate(lambda d: d["stages"]["gen"].update(prompt="yes")), "`prompt:` is 'yes'"),
    ("params-list", _mutate(lambda d: d["stages"]["gen"].update(params=[1])), "`params:` is a list"),
    ("bad-stage-name", _mutate(lambda d: d["stages"].update({"2nd": {"run": "gen.py"}})), "invalid stage name"),
    (
        "profile-unknown-stage",
        _mutate(lambda d: d["profiles"]["small"].update(gne={"n": 1})),
        "profile 'small' names unknown stage 'gne'",
    ),
    (
        "profile-unknown-param",
        _mutate(lambda d: d["profiles"]["small"]["gen"].update(m=1)),
        "profile 'small' sets unknown param 'm'",
    ),
    (
        "profile-wrong-type",
        _mutate(lambda d: d["profiles"]["small"]["gen"].update(n="three")),
        "profile 'small' sets n='three' (a string), but the default 3 is an integer",
    ),
    (
        "profile-bad-engine",
        _mutate(lambda d: d["profiles"]["small"]["gen"].update(engine="x")),
        "profile 'small' sets engine 'x'",
    ),
    (
        "default-profile-unknown",
        _mutate(lambda d: d.update(default_profile="huge")),
        "default_profile 'huge' is not a profile",
    ),
    (
        "program-missing",
        _mutate(lambda d: d["stages"]["upper"].update(run="nope.py")),
        "stage 'upper': program 'nope.py' does not exist",
    ),
    (
        "code-path-missing",
        _mutate(lambda d: d["stages"]["gen"].update(code=["libs"])),
        "stage 'gen': code path 'libs' does not exist",
    ),
    (
        "program-not-executable",
        _mutate(lambda d: d["stages"]["upper"].update(run="lib/helpers.txt")),
        "is not executable",
    ),
]

FLAGS = [  # (id, extra argv, expected words)
    ("set-unknown-param", ["--set", "gen.m=1"], "--set sets unknown param 'm'"),
    ("set-no-equals", ["--set", "gen.n"], "expected STAGE.PARAM=VALUE"),
    ("set-unknown-stage", ["--set", "gne.n=1"], "unknown stage 'gne'"),
    ("set-wrong-type", ["--set", "gen.n=0.5"], "n=0.5 (a number), but the default 3 is an integer"),
    ("set-bool-for-float", ["--set", "upper.scale=true"], "is a number"),
    ("set-bad-engine", ["--set", "gen.engine=turbo"], "sets engine 'turbo'"),
    ("profile-unknown", ["--profile", "huge"], "unknown profile 'huge'"),
    ("from-unknown", ["--from", "nope"], "--from nope: unknown stage"),
    ("force-outside", ["--only", "gen", "--force", "join"], "--force join: not among the stages"),
    ("use-missing-file", ["--use", "gen=/no/such/file.txt"], "no such file or folder"),
    ("use-no-equals", ["--use", "gen"], "expected STAGE=PATH"),
]


@pytest.mark.parametrize("case", BROKEN, ids=[c[0] for c in BROKEN])
def test_broken_pipeline(project, capsys, case):
    _, change, expected = case
    path = project.root / "pipeline.yaml"
    (project.root / "lib" / "helpers.txt").write_text("not a program")
    if isinstance(change, str):
        path.write_text(change)
    else:
        path.write_text(yaml.safe_dump(change(yaml.safe_load(path.read_text())), sort_keys=False))
    _one_clear_line(project, capsys, ["p", "--dry-run"], expected)


@pytest.mark.parametrize("case", FLAGS, ids=[c[0] for c in FLAGS])
def test_bad_flag(project, capsys, case):
    _, argv, expected = case
    _one_clear_line(project, capsys, ["p", "--dry-run", *argv], expected)


def _one_clear_line(project, capsys, argv, expected):
    rc, out, err = project.cli("run", *argv, capsys=capsys)
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert len(lines) == 1 and lines[0].startswith("holoflow: error: "), err
    assert expected in lines[0] and "fix:" in lines[0], lines[0]
    assert not (project.store / "objects").exists()  # nothing was run or written


def test_missing_pipeline_file(tmp_path, capsys, monkeypatch):
    from holoflow.commands import main

    monkeypatch.chdir(tmp_path)
    assert main(["status"]) == 2
    err = capsys.readouterr().err
    assert "no such pipeline file" in err and len(err.strip().splitlines()) == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root can write anywhere")
def test_unwritable_store(project, capsys, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir(mode=0o555)
    rc, out, err = project.cli("run", "p", "--store", str(ro / "store"), capsys=capsys)
    assert rc == 2 and "is not writable" in err and len(err.strip().splitlines()) == 1


def test_store_path_is_a_file(project, capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc, out, err = project.cli("run", "p", "--store", str(blocker / "store"), capsys=capsys)
    assert rc == 2 and "is not writable" in err and len(err.strip().splitlines()) == 1


def test_fixture_pipeline_is_valid():
    from holoflow.flow import pipeline

    p = pipeline.load(FIXTURES / "pipeline.yaml")
    assert list(p.stages) == ["gen", "upper", "join"]


@pytest.mark.parametrize(
    "tail, words",
    [
        ("MemoryError: Unable to allocate 512. MiB", "out of memory"),
        ("RuntimeError: can't start new thread", "out of memory or of threads"),
        ("OSError: [Errno 28] No space left on device", "a disk is full"),
        ("ValueError: bad shape", None),
    ],
)
def test_exit_reason_reads_the_log_tail(tail, words):
    # a step's exit code alone says nothing of why; the words come from what its log says
    from holoflow.flow.executors.failure import exit_reason

    reason = exit_reason(1, "Traceback (most recent call last):\n" + tail)
    assert reason.startswith("exit code 1")
    assert (words in reason) if words else reason == "exit code 1"
    assert exit_reason(-9, tail) == "killed by signal 9"

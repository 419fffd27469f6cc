"""pipeline.yaml resolution: profiles, --set typing, DAG order; cache-key reasons; the real pipeline loads."""

from pathlib import Path

import pytest

from holoflow.flow import pipeline
from holoflow.flow.cachekey import cache_key, components, reasons, source_digest

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).parent / "fixtures"


def test_profile_then_set_precedence():
    p = pipeline.load(FIXTURES / "pipeline.yaml")
    r = pipeline.resolve(p, "big", ["gen.n=7"])
    assert r["gen"].engine == "fancy" and r["gen"].params["n"] == 7
    assert r["gen"].overrides == {"n": "--set", "engine": "profile big"}
    assert pipeline.resolve(p)["gen"].params["n"] == 2  # default_profile small


@pytest.mark.parametrize(
    "item, key, value",
    [
        ("upper.scale=1", "scale", 1.0),  # int accepted for a float param, stored as float
        ("upper.mode=123", "mode", "123"),  # a string param keeps the text
        ("upper.mode=", "mode", ""),
        ("upper.mode=null", "mode", "null"),
        ("gen.fail=true", "fail", True),
        ("upper.sleep=2.5e-1", "sleep", 0.25),
    ],
)
def test_set_typing(item, key, value):
    p = pipeline.load(FIXTURES / "pipeline.yaml")
    stage = item.split(".")[0]
    got = pipeline.resolve(p, None, [item])[stage].params[key]
    assert got == value and type(got) is type(value)


def test_real_pipeline_is_valid_and_ordered():
    p = pipeline.load(ROOT / "pipeline.yaml")
    order = list(p.stages)
    for s in p.stages.values():
        assert all(order.index(u) < order.index(s.name) for u in s.inputs.values())
    for prof in p.profiles:
        pipeline.resolve(p, prof)
    assert p.downstream({"detail"}) >= {"tangent_depth", "transfer_opt"}
    assert "base_pano" in p.upstream({"point_cloud"})


def test_python_digest_ignores_comments_not_code():
    a = source_digest(".py", b"x = 1  # one\n")
    assert a == source_digest(".py", b"# header\n\nx  =  1\n")
    assert a != source_digest(".py", b"x = 2\n")
    assert source_digest(".txt", b"a") != source_digest(".txt", b"a ")


def test_reasons_in_words():
    old = components(
        "detail",
        {"a.py": "1"},
        "classical",
        {"strength": 0.5},
        {"pano": {"stage": "upscale", "tree": "t1"}},
        0,
        "cabin",
    )
    new = components(
        "detail",
        {"a.py": "2"},
        "controlnet_tile",
        {"strength": 0.7},
        {"pano": {"stage": "upscale", "tree": "t2"}},
        1,
        "temple",
    )
    assert cache_key(old) != cache_key(new) and cache_key(old) == cache_key(dict(old))
    assert reasons(old, new) == [
        "engine changed: classical -> controlnet_tile",
        "params changed: detail.strength 0.5 -> 0.7",
        "code changed: a.py",
        "input changed: upscale",
        "seed changed: 0 -> 1",
        'prompt changed: "cabin" -> "temple"',
    ]


def test_a_stage_only_used_stages_read_is_not_run():
    """`--use metric_align=...`: tangent_depth, which only metric_align reads, has nothing to do; a stage
    named on the command line, or another reader of it, still brings it in."""
    from holoflow.flow.context import Options, select

    p = pipeline.load(ROOT / "pipeline.yaml")
    used = {"base_pano": Path("pano.exr"), "metric_align": Path("depth.exr")}
    selected, needed, _ = select(p, Options(), used)
    assert "tangent_depth" not in selected | needed
    assert {"base_pano", "metric_align", "point_cloud", "export"} <= needed and "metric_align" in selected
    assert selected == set(p.stages) - {"tangent_depth"}
    selected, needed, _ = select(p, Options(force=["tangent_depth"]), used)
    assert "tangent_depth" in selected & needed  # asked for by name
    selected, needed, _ = select(p, Options(until="tangent_depth"), used)
    assert "tangent_depth" in selected & needed
    selected, needed, _ = select(p, Options(), {"base_pano": Path("pano.exr")})
    assert selected == needed == set(p.stages)  # nothing used downstream: every stage runs
    # the fixture's join reads gen besides upper: --use upper keeps gen
    f = pipeline.load(FIXTURES / "pipeline.yaml")
    assert select(f, Options(), {"upper": Path("u.txt")})[0] == {"gen", "upper", "join"}

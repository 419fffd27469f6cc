"""Typed stage parameters (holoflow/flow/params.py): one source of truth, checked overrides with one-line
errors, engine registries checked against pipeline.yaml, and nothing heavy on the CLI's path."""

import dataclasses
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from holoflow.flow import pipeline
from holoflow.flow.params import ParamError
from holoflow.recon.config import PreOptParams, TransferOptParams

ROOT = Path(__file__).resolve().parents[2]


def _pipeline(tmp_path, pre_opt_block: str) -> Path:
    """The real pipeline.yaml with the pre_opt stage's block replaced (keys under `  pre_opt:`)."""
    text = (ROOT / "pipeline.yaml").read_text()
    start = text.index("  pre_opt:\n")
    end = text.index("\n\n", start)
    (tmp_path / "pipeline.yaml").write_text(text[:start] + "  pre_opt:\n" + pre_opt_block + text[end:])
    return tmp_path / "pipeline.yaml"


def test_every_stage_of_the_pipeline_has_a_class_whose_defaults_it_runs():
    pipe = pipeline.load(ROOT / "pipeline.yaml")
    for s in pipe.stages.values():
        assert s.config is not None, s.name
        assert s.params == s.config.defaults(), s.name  # pipeline.yaml overrides nothing
        for f in dataclasses.fields(s.config):
            assert f.metadata["doc"], (s.name, f.name)


@pytest.mark.parametrize(
    "item, message",
    [
        ("pre_opt.init_opacty=0.3", "unknown param 'init_opacty'; fix: params are: init_opacity, "),
        ("pre_opt.init_opacity=1.5", "init_opacity=1.5 is outside the valid range > 0 and < 1; fix: "),
        ("pre_opt.pcd_iters=ten", "pcd_iters='ten' is a string, expected int; fix: give pcd_iters an integer"),
        ("pre_opt.pcd_iters=2.5", "pcd_iters=2.5 is a number, expected int"),
        (
            "tangent_depth.align=grd",
            "align='grd' is not one of median, affine, grid; fix: use one of: "
            "median, affine, grid (did you mean 'grid'?)",
        ),
        ("tangent_depth.grid=[8]", "grid=[8] is a list, expected tuple[int, int]"),
    ],
)
def test_bad_override_is_one_line_with_the_fix(item, message):
    pipe = pipeline.load(ROOT / "pipeline.yaml")
    with pytest.raises(pipeline.PipelineError) as e:
        pipeline.resolve(pipe, None, [item])
    text = str(e.value)
    assert "\n" not in text and message in text and text.startswith("pipeline.yaml: stage '")
    if "init_opacty" in item:
        assert "(did you mean 'init_opacity'?)" in text


def test_override_types_are_canonical_and_hash_as_plain_values():
    pipe = pipeline.load(ROOT / "pipeline.yaml")
    r = pipeline.resolve(
        pipe, None, ["pre_opt.init_opacity=1.0e-1", "tangent_depth.grid=[3, 4]", "pre_opt.densify_stop=1"]
    )
    assert r["pre_opt"].params["init_opacity"] == 0.1
    assert r["pre_opt"].params["densify_stop"] == 1.0 and type(r["pre_opt"].params["densify_stop"]) is float
    assert r["tangent_depth"].params["grid"] == [3, 4]  # a list, as JSON reads it back
    json.dumps(r["tangent_depth"].params)


def test_bad_value_in_pipeline_yaml_params_or_a_profile_fails_at_load(tmp_path):
    block = (
        "    run: stages/pre_opt.py\n    engine: cpu\n    engines: [cpu, gsplat]\n"
        "    config: holoflow.recon.config:PreOptParams\n    params: {max_gaussians: -1}"
    )
    with pytest.raises(
        pipeline.PipelineError, match=r"`params:` sets max_gaussians=-1 is outside the valid range >= 1"
    ):
        pipeline.load(_pipeline(tmp_path, block))


def test_pipeline_params_override_the_class_defaults(tmp_path):
    block = (
        "    run: stages/pre_opt.py\n    engine: cpu\n    engines: [cpu, gsplat, auto]\n"
        "    config: holoflow.recon.config:PreOptParams\n    params: {pcd_iters: 7}"
    )
    pipe = pipeline.load(_pipeline(tmp_path, block))
    assert pipeline.resolve(pipe)["pre_opt"].params == {**PreOptParams.defaults(), "pcd_iters": 7}


def test_registry_rejects_an_engine_pipeline_yaml_lists_but_nobody_registered(tmp_path):
    block = (
        "    run: stages/pre_opt.py\n    engine: cpu\n    engines: [cpu, gsplatt, auto]\n"
        "    config: holoflow.recon.config:PreOptParams"
    )
    with pytest.raises(pipeline.PipelineError) as e:
        pipeline.load(_pipeline(tmp_path, block))
    assert str(e.value) == (
        "pipeline.yaml: stage 'pre_opt': engine 'gsplatt' is not registered for "
        "PreOptParams; fix: use one of: cpu, gsplat, reference, auto (did you mean 'gsplat'?)"
    )


def test_config_must_name_a_param_class(tmp_path):
    block = "    run: stages/pre_opt.py\n    engine: cpu\n    config: holoflow.recon.config:Nope"
    with pytest.raises(pipeline.PipelineError, match="`config: holoflow.recon.config:Nope` cannot be loaded"):
        pipeline.load(_pipeline(tmp_path, block))


def test_direct_construction_is_checked_too():
    with pytest.raises(ParamError, match="init_opacity=0.0 is outside the valid range > 0 and < 1"):
        PreOptParams(init_opacity=0.0)
    with pytest.raises(ParamError, match="unknown param 'preview'"):
        TransferOptParams.from_params({"preview": 64})
    assert TransferOptParams.from_params({"iters": 3}).iters == 3


def test_every_registered_engine_resolves_to_a_callable():
    pipe = pipeline.load(ROOT / "pipeline.yaml")
    for s in pipe.stages.values():
        for name in s.config.ENGINES.targets:
            assert callable(s.config.ENGINES.get(name)), (s.name, name)
    with pytest.raises(ValueError, match="unknown engine 'nope'; registered: cpu, gsplat, reference"):
        PreOptParams.ENGINES.get("nope")
    with pytest.raises(ValueError, match="'auto' is chosen when the step runs"):  # a chooser, resolved first
        PreOptParams.ENGINES.get("auto")


def test_param_classes_and_the_params_command_import_no_heavy_library():
    code = (
        "import sys, holoflow.commands as c; c.main(['params', 'pre_opt']); "
        "bad = [m for m in ('torch', 'numpy', 'cv2', 'scipy') if m in sys.modules]; "
        "print('HEAVY', bad)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "HEAVY []" in out.stdout and re.search(r"pcd_iters +int +10 ", out.stdout)

"""`holoflow bench paper --truth`: the run it asks for needs no weights and keeps the truth's panorama."""

from pathlib import Path

import pytest

from holoflow.bench.paper import truth_run_args
from holoflow.flow import pipeline
from holoflow.networks.manifest import needs

ROOT = Path(__file__).resolve().parents[2]


def _split(args: list[str]) -> tuple[list[str], list[str]]:
    uses = [args[i + 1] for i in range(0, len(args), 2) if args[i] == "--use"]
    sets = [args[i + 1] for i in range(0, len(args), 2) if args[i] == "--set"]
    assert len(uses) + len(sets) == len(args) // 2
    return uses, sets


@pytest.mark.parametrize("way", ["exact", "simulated"])
def test_truth_run_needs_no_weights_and_keeps_the_panorama(way):
    args = truth_run_args(Path("/data/room"), way, 2048, models=None)
    uses, sets = _split(args)
    assert uses[0] == "base_pano=/data/room/pano_z.exr"
    assert ("metric_align=/data/room/pano_z.exr" in uses) == (way == "exact")
    resolved = pipeline.resolve(pipeline.load(ROOT / "pipeline.yaml"), "paper", sets)
    used = {u.split("=")[0] for u in uses}  # --use'd stages never run
    assert [n.role for n in needs(resolved) if n.stage not in used] == []  # runs where no weights are
    assert resolved["upscale"].params["max_width"] == 2048 and resolved["detail"].params["max_width"] == 2048
    assert resolved["stylize"].params["style"] == "none" and resolved["detail"].params["strength"] == 0
    assert resolved["pre_opt"].params["pcd_iters"] == 2000  # the profile's reconstruction is untouched
    assert resolved["pre_opt"].engine == "auto" and resolved["transfer_opt"].params["iters"] == 5000
    expected_depth = {"exact": "given", "simulated": "simulated"}[way]
    assert resolved["tangent_depth"].engine == expected_depth


def test_truth_run_keeps_lama_with_models():
    _, sets = _split(truth_run_args(Path("/data/room"), "exact", 2048, models="/models"))
    resolved = pipeline.resolve(pipeline.load(ROOT / "pipeline.yaml"), "paper", sets)
    assert resolved["inp_set"].engine == "lama"

"""Compile ahead (holoflow/flow/executors/ahead.py): the kernels a run compiles before its steps need them
are the ones, and the only specializations, that the stages' calls then use; every kernel file takes part."""

import json
import re
import subprocess
import sys
from pathlib import Path

from holoflow.flow.cachekey import CodeHasher
from holoflow.flow.executors.ahead import HOOK, modules_for

ROOT = Path(__file__).resolve().parents[2]

# In a fresh interpreter (other tests compile other dtypes in this one): every compile_ahead, the
# signatures each kernel then has, then the calls the stages make at the preview's sizes (a float32
# GaussianModel of more than PARALLEL_MIN_WORK Gaussians, as P_f's 10^5 are, rendered and
# differentiated with and without depth, below and above PARALLEL_MIN_GAUSSIANS;
# a float32 background layer; a float64 cloud through the z-buffer), and the signatures after.
PROBE = r"""
import importlib, json, sys
import numba, torch

hooks, files = sys.argv[1].split(","), sys.argv[2].split(",")

def kernels():
    out = {}
    for f in files:
        mod = importlib.import_module(f[:-3].replace("/", "."))
        for name, d in vars(mod).items():
            if isinstance(d, numba.core.dispatcher.Dispatcher) and d.py_func.__module__ == mod.__name__:
                out[mod.__name__ + "." + name] = [str(s) for s in d.signatures]
    return out

for f in hooks:
    importlib.import_module(f[:-3].replace("/", ".")).compile_ahead()
ahead = kernels()

from holoflow.geometry.layers import background_layer
from holoflow.geometry.pointcloud import project_points_zbuffer
from holoflow.splat.composite_cpu import PARALLEL_MIN_GAUSSIANS
from holoflow.splat.project_cpu import PARALLEL_MIN_WORK
from holoflow.splat.model import GaussianModel
from holoflow.splat.rasterize import render
from holoflow.splat.synthetic import intrinsics, surface_scene

for n, depth in ((PARALLEL_MIN_WORK + 5000, True), (2 * PARALLEL_MIN_GAUSSIANS, False)):
    s = surface_scene(n, seed=1)
    model = GaussianModel.from_points(s["means"].numpy(), s["colors"].numpy(), scales=s["scales"].numpy(),
                                    quats=s["quats"].numpy())
    out = render(model, torch.eye(4)[None], intrinsics(48, 32)[None], 48, 32, depth=depth)
    out["rgb"].sum().backward()
d = torch.full((8, 16), 2.0)
d[:, :4] = 1.0
background_layer(torch.rand(8, 16, 3), d, torch.ones(8, 16, dtype=torch.bool), 0.5)
xyz = torch.rand(100, 3, dtype=torch.float64) + torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
project_points_zbuffer(xyz, torch.rand(100, 3, dtype=torch.float64), intrinsics(16, 16).double(),
                       torch.eye(4, dtype=torch.float64), 16, 16)
json.dump({"ahead": ahead, "after": kernels()}, sys.stdout)
"""

# called from Python (the others are helpers compiled inside their callers); the serial twins run
# for views and clouds below the parallel thresholds only, compile_ahead leaves them to first use
ENTRY = (
    [
        "holoflow.splat.composite_cpu." + k
        for k in (
            "_boxes",
            "_bin_tiles",
            "_forward",
            "_backward",
            "_gather_grads",
            "_boxes_serial",
            "_bin_tiles_serial",
        )
    ]
    + [
        "holoflow.splat.project_cpu." + k
        for k in ("_project_test", "_count_chunks", "_project_write", "_project_bwd_pairs", "_project_bwd_params")
    ]
    + ["holoflow.geometry.zbuffer_cpu.zbuffer", "holoflow.geometry.layers._grow", "holoflow.recon.inpaint._walk"]
)
LEFT = [
    "holoflow.splat.composite_cpu._forward_serial",
    "holoflow.splat.composite_cpu._backward_serial",
    "holoflow.splat.composite_cpu._gather_grads_serial",
] + [
    "holoflow.splat.project_cpu." + k + "_serial"
    for k in ("_project_test", "_count_chunks", "_project_write", "_project_bwd_pairs", "_project_bwd_params")
]


def kernel_files() -> list[str]:
    """The project's files that define numba kernels."""
    return sorted(
        str(p.relative_to(ROOT)) for p in (ROOT / "holoflow").rglob("*.py") if re.search(r"^@njit", p.read_text(), re.M)
    )


def hook_files() -> list[str]:
    """The project's files that define ``compile_ahead``."""
    return sorted(str(p.relative_to(ROOT)) for p in (ROOT / "holoflow").rglob("*.py") if HOOK.search(p.read_text()))


def test_every_kernel_file_is_compiled_ahead():
    # the splatting kernels (cpu.py, cpu_project.py) are compiled by rasterize's compile_ahead
    assert set(kernel_files()) - set(hook_files()) == {
        "holoflow/splat/composite_cpu.py",
        "holoflow/splat/project_cpu.py",
    }
    assert set(hook_files()) - set(kernel_files()) == {"holoflow/splat/rasterize.py"}


def test_compile_ahead_covers_the_stages_calls():
    r = subprocess.run(
        [sys.executable, "-c", PROBE, ",".join(hook_files()), ",".join(kernel_files())],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout)
    ahead, after = got["ahead"], got["after"]
    for k in ENTRY:
        assert len(ahead[k]) == 1, (k, ahead[k])  # one specialization each
    for k in LEFT:
        assert ahead[k] == [], (k, ahead[k])
    for k in ENTRY + LEFT:
        assert after[k] == ahead[k], (k, after[k])  # the stages' calls compile nothing more


def test_a_run_compiles_ahead_what_its_stages_import_in_their_order():
    hasher = CodeHasher(ROOT, None)
    closures = [
        hasher.files(ROOT / "stages" / f"{s}.py") for s in ("tangent_depth", "point_cloud", "pre_opt", "transfer_opt")
    ]
    got = modules_for(closures)  # point_cloud's first, then pre_opt's (each step's: any order)
    assert set(got[:2]) == {f"{ROOT}:holoflow.geometry.{m}" for m in ("zbuffer_cpu", "layers")}
    assert set(got[2:]) == {f"{ROOT}:holoflow.splat.rasterize", f"{ROOT}:holoflow.recon.inpaint"}
    assert len(got) == 4 and modules_for(closures[:1]) == []

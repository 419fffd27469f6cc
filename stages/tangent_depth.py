"""tangent_depth: the panorama (downsampled to ``width``) -> 20 padded icosahedron tangent faces ->
relative disparity per face (engine, holoflow.depth.config.TangentDepthParams.ENGINES; ``auto`` by
holoflow.depth.engines.resolve_engine) -> per-face alignment (``align``: median | affine | grid) ->
frustum blending. Writes disparity.exr (Y = relative radial disparity), faces/face_NN.exr (raw.Y =
engine output, aligned.Y = aligned radial disparity; where a pixel is invalid, a NaN / inf of the engine
(0 in both) or a face the alignment dropped (aligned 0), a valid.Y channel is 0 there, 1 elsewhere) and
alignment.json (residuals, node grids).
With a truth depth (Z in the truth panorama) it records how well the disparity can score after the
best global scale + offset (docs/depth.md)."""

from __future__ import annotations

import json


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    import numpy as np

    from holoflow.depth import panorama as pd
    from holoflow.depth.config import TangentDepthParams
    from holoflow.depth.engines import resolve_engine, truth_source
    from holoflow.depth.inputs import read_pano, read_truth
    from holoflow.geometry.sampling import resize_pano
    from holoflow.io.exr import write_exr

    cfg = job.config(TangentDepthParams)
    pano = resize_pano(read_pano(job.input_file("pano", "pano.exr")), cfg.width)
    truth = read_truth(job.inputs.get("truth"))
    engine, why = resolve_engine(
        job.engine, truth is not None, source=truth_source(job.inputs.get("truth")), network=cfg.model
    )
    result = pd.estimate_disparity(pano, truth, engine, cfg, job.seed, job.device, job.progress)
    result.engine["why"] = why
    attrs = {
        "holoflow.stage": "tangent_depth",
        "holoflow.depth_kind": "disparity",
        "holoflow.engine": result.engine["engine"],
        "holoflow.simulation": int(bool(result.engine.get("simulation"))),
    }
    write_exr(job.output("disparity.exr"), {"Y": result.disparity}, attrs)
    for f in range(result.raw.shape[0]):
        valid = np.isfinite(result.raw[f]) & np.isfinite(result.aligned[f])
        channels = {
            "raw.Y": np.where(np.isfinite(result.raw[f]), result.raw[f], 0.0),
            "aligned.Y": np.where(valid, result.aligned[f], 0.0),
        }
        if not valid.all():  # an engine's NaN / inf (0 in both), or a dropped face (aligned 0): said per pixel
            channels["valid.Y"] = valid.astype(np.float32)
        write_exr(
            job.output(f"faces/face_{f:02d}.exr"),
            channels,
            {**attrs, "holoflow.face": f, "holoflow.face_ok": int(result.alignment.face_ok[f])},
        )
    al = result.alignment
    report = {
        "engine": result.engine,
        "residuals": al.residuals,
        "norm": al.norm.tolist(),
        "face_ok": al.face_ok.astype(int).tolist(),
        "scale_grid": np.round(al.scale, 8).tolist(),
        "offset_grid": np.round(al.offset, 8).tolist(),
    }
    job.output("alignment.json").write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
    meta = {
        "engine": result.engine,
        "align": al.residuals["method"],
        "overlap_rel_rms": al.residuals["rel_rms"],
        "dropped_faces": al.residuals["dropped_faces"],
    }
    if truth is not None:
        meta["truth_oracle_affine"] = pd.oracle_metrics(result.disparity, truth)
    job.meta(**meta)
    print(f"tangent_depth: engine {result.engine['engine']} ({result.engine['why']})", flush=True)
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "tangent_depth")

"""metric_align: metric depth (engine) on a seeded random subset of ``faces`` tangent faces, turned
into radial disparity references; one global scale + offset maps the blended disparity onto them
(Huber IRLS on relative residuals); blended pixels at the sky's border that are mostly sky are made
sky (docs/depth.md, step 6); a network's depth then gets sharp steps (holoflow/depth/edges.py) and is
straightened by the room's planes (holoflow/depth/planes.py; param ``refine``). Writes depth.exr (Z =
radial metres, +inf sky; a refined depth's header says the noise it had before the planes,
``holoflow.depth_noise``, for point_cloud's smoothing) and metric_align.json (scale, offset, residuals,
faces used, the refinement's facts); with a truth depth it records AbsRel, RMSE and delta1 of the
result (docs/depth.md). Engine ``given`` (``auto`` on a panorama imported with its own Z channel):
the given Z, resized to the disparity's grid (nearest), is the depth as it is."""

from __future__ import annotations

import json


def main() -> int:
    from holoflow.stage import Job

    job = Job.from_argv()
    from holoflow.depth import panorama as pd
    from holoflow.depth.config import MetricAlignParams
    from holoflow.depth.engines import resolve_engine, truth_source
    from holoflow.depth.inputs import read_disparity, read_pano, read_truth
    from holoflow.geometry.sampling import resize_pano
    from holoflow.io.exr import write_exr

    cfg = job.config(MetricAlignParams)
    disparity, relative_engine = read_disparity(job.input_file("disparity", "disparity.exr"))
    pano = resize_pano(read_pano(job.input_file("pano", "pano.exr")), disparity.shape[1])
    truth = read_truth(job.inputs.get("truth"))
    engine, why = resolve_engine(
        job.engine, truth is not None, source=truth_source(job.inputs.get("truth")), metric=True
    )
    if engine == "given":
        if truth is None:
            raise ValueError("engine 'given' needs a Z channel (radial depth) in the imported panorama")
        depth = pd.resize_radial(truth, *disparity.shape).astype("float32")
        facts = {"engine": "given", "why": why, "note": "the imported panorama's own Z channel, kept as the depth"}
        report = {"engine": facts, "faces": []}
    else:
        result = pd.metric_from_disparity(
            disparity, pano, truth, engine, cfg, job.seed, job.device, job.progress, relative_engine=relative_engine
        )
        depth, facts = result.depth, {**result.engine, "why": why}
        report = {"engine": facts, "faces": result.faces, **result.fit}
        if truth is not None:
            report["truth_metrics"] = pd.score(depth, truth)
    write_exr(
        job.output("depth.exr"),
        {"Z": depth},
        {
            "holoflow.stage": "metric_align",
            "holoflow.depth_kind": "radial",
            "holoflow.engine": facts["engine"],
            "holoflow.simulation": int(bool(facts.get("simulation"))),
            **({"holoflow.depth_noise": report["depth_noise"]} if "depth_noise" in report else {}),
        },
    )
    job.output("metric_align.json").write_text(json.dumps(report, indent=1, sort_keys=True) + "\n")
    job.meta(**report)
    print(f"metric_align: engine {facts['engine']} ({facts['why']})", flush=True)
    return 0


if __name__ == "__main__":
    from holoflow.stage import run_main

    run_main(main, "metric_align")

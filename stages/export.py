"""export: the final scene (transfer_opt's scene.ply) in the formats other tools read, and the
panorama's RGB-D as a mesh. Writes, as ``formats`` selects (default all): scene.spz (Niantic SPZ,
RUB axes), scene.splat (antimatter15, 32 bytes a Gaussian), scene.compressed.ply (PlayCanvas /
SuperSplat), scene.glb (glTF KHR_gaussian_splatting, +Y up) and mesh.glb (vertex-coloured triangles
from detail's pano.exr and metric_align's depth.exr at P_f's resolution, depth discontinuities cut,
sky as a far dome or left out). Formats, axes and error bounds: holoflow/export/, docs/viewers.md.
"""

from __future__ import annotations

from holoflow.stage import Job, run_main


def main() -> int:
    job = Job.from_argv()
    from holoflow.export.config import FORMATS, ExportParams
    from holoflow.export.mesh import panorama_mesh_glb
    from holoflow.io.exr import read_radial_depth, read_rgb
    from holoflow.io.ply import read_gaussians

    cfg = job.config(ExportParams)
    formats = cfg.format_list
    fields = read_gaussians(job.input_file("scene", "scene.ply"))
    sizes = ExportParams.ENGINES.get(job.engine)(fields, job.output_dir, formats, job.cpus)
    mesh_info = {}
    if "mesh" in formats:
        data, mesh_info = panorama_mesh_glb(
            read_rgb(job.input_file("pano", "pano.exr")),
            read_radial_depth(job.input_file("depth", "depth.exr")),
            cfg.mesh_width,
            cfg.mesh_edge_threshold,
            cfg.mesh_sky,
            cfg.sky_radius,
        )
        job.output(FORMATS["mesh"]).write_bytes(data)
        sizes[FORMATS["mesh"]] = len(data)
    job.meta(gaussians=len(fields["x"]), bytes=sizes, **mesh_info)
    print(f"export: {len(fields['x'])} Gaussians -> {', '.join(f'{k} ({v / 1e6:.2f} MB)' for k, v in sizes.items())}")
    return 0


if __name__ == "__main__":
    run_main(main, "export")

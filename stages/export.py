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
    import torch

    from holoflow.export.config import FORMATS, ExportParams
    from holoflow.export.gltf import mesh_glb_bytes
    from holoflow.export.mesh import rgbd_mesh
    from holoflow.geometry.pointcloud import resample_rgbd
    from holoflow.io.exr import read_exr, read_rgb
    from holoflow.io.ply import read_gaussians

    cfg = job.config(ExportParams)
    formats = cfg.format_list
    fields = read_gaussians(job.input_file("scene", "scene.ply"))
    sizes = ExportParams.ENGINES.get(job.engine)(fields, job.output_dir, formats, job.cpus)
    mesh_info = {}
    if "mesh" in formats:
        rgb = torch.from_numpy(read_rgb(job.input_file("pano", "pano.exr"))).double()   # [H, W, 3] linear
        channels, attrs = read_exr(job.input_file("depth", "depth.exr"))
        if "Z" not in channels or attrs.get("holoflow.depth_kind", "radial") != "radial":
            raise ValueError("depth.exr must hold radial depth in channel Z (metric_align's output)")
        depth = torch.from_numpy(channels["Z"]).double()                                # [H, W] metres
        width = cfg.mesh_width or max(2, depth.shape[1] // 2)
        col, d = resample_rgbd(rgb, depth, width)                                      # [h, w, 3], [h, w]
        verts, cols, faces = rgbd_mesh(col.clamp(0, 1).numpy(), d.numpy(), cfg.mesh_edge_threshold,
                                       cfg.mesh_sky, cfg.sky_radius)
        data = mesh_glb_bytes(verts, cols, faces)
        job.output(FORMATS["mesh"]).write_bytes(data)
        sizes[FORMATS["mesh"]] = len(data)
        mesh_info = {"mesh_grid": [int(d.shape[0]), int(d.shape[1])], "mesh_vertices": int(len(verts)),
                     "mesh_faces": int(len(faces))}
    job.meta(gaussians=len(fields["x"]), bytes=sizes, **mesh_info)
    print(f"export: {len(fields['x'])} Gaussians -> {', '.join(f'{k} ({v / 1e6:.2f} MB)' for k, v in sizes.items())}")
    return 0


if __name__ == "__main__":
    run_main(main, "export")

"""File formats: EXR images (holoflow.io.exr) and PLY point clouds / Gaussians (holoflow.io.ply)."""

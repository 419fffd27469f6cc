"""Exports of the final scene to the formats other tools read (docs/viewers.md).

- :mod:`holoflow.export.splats`: activated Gaussians, the holoflow -> +Y-up axis change, and writers
  for Niantic SPZ, the antimatter15 ``.splat`` and the PlayCanvas compressed PLY;
- :mod:`holoflow.export.gltf`: a GLB writer, Gaussians as ``KHR_gaussian_splatting`` and the RGB-D
  mesh as a vertex-coloured triangle mesh;
- :mod:`holoflow.export.mesh`: the panorama's RGB-D as a triangle mesh, depth discontinuities cut.

Only numpy is needed to write Gaussians; the mesh resamples the panorama with torch.
"""

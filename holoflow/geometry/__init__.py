"""Spherical and pinhole geometry shared by every panorama, depth and reconstruction stage.

Conventions (docs/conventions.md): world = OpenCV frame of the panorama centre (+x right, +y down,
+z forward); equirect pixel centres at +0.5; pinhole K with pixel centres at +0.5; viewmat = 4x4
world-to-camera, OpenCV axes; quaternions (w, x, y, z). API list: docs/geometry.md.
Submodules: sphere, camera, sampling, icosahedron, rigs, pointcloud, export.
"""

"""Panorama depth (docs/depth.md): 360MonoDepth-style tangent-face disparity, per-face alignment
(median / affine / grid), frustum blending, robust global metric alignment, depth metrics vs truth.

Submodules: ``faces`` (face pixel geometry, overlaps), ``align`` (solvers), ``engines`` (simulated,
prior, real-network dispatch), ``metric`` (robust global fit), ``metrics`` (AbsRel, RMSE, delta1),
``panorama`` (the pipeline the stages and the bench call), ``io`` (stage inputs).
"""

"""Enhanced Two-Stage Panorama Reconstruction: view sets, the pre / transfer optimisation schedules,
the INP set (missing masks + inpainting) and previews. docs/reconstruction.md."""

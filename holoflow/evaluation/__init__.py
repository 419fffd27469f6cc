"""Scoring reconstructions (`holoflow eval`, the accuracy benches): cameras to score at and their true
renders (cameras.py), PSNR / SSIM / NIQE / BRISQUE of the two models of a run (scores.py), running the
pipeline for a scene and reading what made its depth (runs.py), the report's tables (tables.py), and
the one line naming the machine a measurement ran on (machine.py). The command: holoflow/commands/evaluate.py."""

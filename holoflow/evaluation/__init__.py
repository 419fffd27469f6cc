"""Scoring reconstructions (`holoflow eval`, the accuracy benches): cameras to score at and their true
renders (cameras.py), PSNR / SSIM / NIQE / BRISQUE of the two models of a run (scores.py), a finished
scene at the viewing size (viewing_size.py), truth sets and a scene scored against one per ring
(truth_set.py, truth_scores.py), running the pipeline for a scene and reading what made its depth
(runs.py), the report's tables (tables.py), and the one line naming the machine a measurement ran on
(machine.py). The commands: holoflow/commands/evaluate.py (evaluate_run.py, evaluate_scenes.py)."""

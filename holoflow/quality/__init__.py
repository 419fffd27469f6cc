"""Image-quality scores: full-reference PSNR / SSIM / SSIM and empty-fraction scores (metrics.py) and the
no-reference NIQE / BRISQUE (nriqa.py). numpy only; used by the recon stages, eval and the benches."""

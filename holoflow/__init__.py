"""holoflow: text prompt -> enclosed 3D Gaussian Splatting scene (HoloDreamer)."""

__version__ = "0.1.0"

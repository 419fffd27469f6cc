"""Procedural scenes: prompt words -> Scene description -> analytic ray casting in torch.

The embedded default of the base_pano stage, and the ground truth of every later stage: a Scene can be
rendered from ANY camera (``render_pinhole``), with exact depth. See docs/panorama.md. Names are
imported lazily, so ``holoflow.scene.model`` (scene.json I/O) does not pull in torch.
"""

from importlib import import_module

_API = {
    "Scene": "model",
    "scene_from_prompt": "generate",
    "render_equirect": "render",
    "render_pinhole": "render",
    "cast": "shade",
}
__all__ = sorted(_API)


def __getattr__(name: str):
    if name in _API:
        return getattr(import_module(f"holoflow.scene.{_API[name]}"), name)
    raise AttributeError(f"module 'holoflow.scene' has no attribute {name!r}")

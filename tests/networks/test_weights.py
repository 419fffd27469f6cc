"""Model resolution: local paths, the HF cache (offline only), one-line errors."""

import pytest
import torch

from holoflow.networks import weights
from holoflow.networks.weights import MissingWeights, load_state_dict, resolve, weight_file

pytestmark = pytest.mark.models
pytest.importorskip("huggingface_hub")


def test_local_dir_and_file(tmp_path):
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "net.pth").write_bytes(b"")
    assert resolve(str(tmp_path / "m"), "realesrgan", "upscale.model") == (tmp_path / "m").resolve()
    assert weight_file(tmp_path / "m", "realesrgan", "upscale.model") == tmp_path / "m" / "net.pth"


def test_missing_local_path_is_one_clear_line(tmp_path):
    with pytest.raises(MissingWeights) as err:
        resolve(str(tmp_path / "nope"), "lama", "inp_set.model")
    msg = str(err.value)
    assert "\n" not in msg and "inp_set.model" in msg and "nope" in msg


def test_no_default_for_lama():
    with pytest.raises(MissingWeights, match="inp_set.model"):
        resolve("", "lama", "inp_set.model")


def test_model_id_not_cached_names_download(tmp_path, monkeypatch):
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(tmp_path / "hub"))
    with pytest.raises(MissingWeights) as err:
        resolve("", "zoedepth", "metric_align.model")
    msg = str(err.value)
    assert "\n" not in msg and "hf download Intel/zoedepth-nyu-kitti" in msg and str(tmp_path / "hub") in msg


def test_model_id_with_subfolder_from_cache(tmp_path, monkeypatch):
    """A repo laid out as huggingface_hub caches it resolves offline, sub-path included."""
    from huggingface_hub import constants

    hub = tmp_path / "hub"
    repo = hub / "models--owner--pano"
    snap = repo / "snapshots" / ("a" * 40)
    (snap / "sd-base" / "unet").mkdir(parents=True)
    (repo / "refs").mkdir()
    (repo / "refs" / "main").write_text("a" * 40)
    monkeypatch.setattr(constants, "HF_HUB_CACHE", str(hub))
    assert resolve("owner/pano/sd-base", "diffusion360", "base_pano.model") == snap / "sd-base"
    with pytest.raises(MissingWeights, match="no 'sr-base'"):
        resolve("owner/pano/sr-base", "tile_base", "detail.model")


def test_weight_file_choice(tmp_path):
    for name in ("RealESRGAN_x2plus.pth", "RealESRGAN_x4plus.pth"):
        (tmp_path / name).write_bytes(b"")
    assert weight_file(tmp_path, "realesrgan", "upscale.model", prefer="x4").name == "RealESRGAN_x4plus.pth"
    with pytest.raises(MissingWeights, match="several weight files"):
        weight_file(tmp_path, "realesrgan", "upscale.model")
    (tmp_path / "empty").mkdir()
    with pytest.raises(MissingWeights, match="no weight file"):
        weight_file(tmp_path / "empty", "realesrgan", "upscale.model")


def test_state_dict_loading_is_safe(tmp_path):
    torch.save({"w": torch.ones(2)}, tmp_path / "ok.pth")
    assert torch.equal(load_state_dict(tmp_path / "ok.pth")["w"], torch.ones(2))
    torch.save({"w": torch.ones(2), "cfg": weights.MissingWeights("x")}, tmp_path / "pickle.pth")
    with pytest.raises(MissingWeights, match="plain state dict"):
        load_state_dict(tmp_path / "pickle.pth")

import pytest


@pytest.fixture(scope="module")
def tiny_truth_set(tmp_path_factory):
    """A truth set folder named ``room``: the small cabin ray cast at 48 px, two views on rings 0 and 0.5 m."""
    from holoflow.evaluation.truth_set import write_truth_set
    from holoflow.scene import scene_from_prompt

    folder = tmp_path_factory.mktemp("truth") / "room"
    scene = scene_from_prompt("a small wooden cabin", 0)
    return write_truth_set(folder, scene, size=48, rings=(0.0, 0.5), per_ring=2, pano_width=128, samples=1)

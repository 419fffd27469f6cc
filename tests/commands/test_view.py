"""`holoflow view` without a browser: what it opens, the splat arrays it hands viser, and the one-line
errors (not a scene, port in use). The browser test is tests/e2e/test_view_browser.py."""

import socket
from contextlib import contextmanager
from types import SimpleNamespace

import numpy as np
import pytest

from holoflow.commands import view
from holoflow.io.ply import write_gaussians, write_points


def _scene(path, n=50, quat=(1.0, 0.0, 0.0, 0.0), scales=(0.1, 0.2, 0.3)):
    """n Gaussians on a line, all with the given rotation (w, x, y, z) and linear scales (metres)."""
    f = {"x": np.linspace(-1, 1, n), "y": np.zeros(n), "z": np.full(n, 2.0), "opacity": np.zeros(n)}
    f.update({f"f_dc_{i}": np.zeros(n) for i in range(3)})
    f.update({f"scale_{i}": np.full(n, np.log(s)) for i, s in enumerate(scales)})
    f.update({f"rot_{i}": np.full(n, q) for i, q in enumerate(quat)})
    write_gaussians(path, f)
    return path


def test_covariance_colour_and_opacity(tmp_path):
    # 45 deg about +z (x towards y): the 0.1 m axis along (1, 1)/sqrt 2, the 0.2 m axis along (-1, 1)/sqrt 2,
    # so var x = var y = (0.01 + 0.04) / 2 and cov xy = (0.01 - 0.04) / 2
    a = np.pi / 8
    s = view.load_splats(_scene(tmp_path / "s.ply", quat=(np.cos(a), 0.0, 0.0, np.sin(a))), cap=100)
    assert s["centers"].shape == (50, 3) and s["opacities"].shape == (50, 1)
    expected = [[0.025, -0.015, 0], [-0.015, 0.025, 0], [0, 0, 0.09]]
    np.testing.assert_allclose(s["covariances"][0], expected, atol=1e-6)
    np.testing.assert_allclose(s["rgbs"], 0.5)  # f_dc = 0: mid grey
    np.testing.assert_allclose(s["opacities"], 0.5)  # logit 0


def test_subsampled_above_the_cap_with_a_message(tmp_path, capsys):
    s = view.load_splats(_scene(tmp_path / "s.ply"), cap=10)
    assert len(s["centers"]) == 10 and len(np.unique(s["centers"][:, 0])) == 10
    assert "showing 10 of them" in capsys.readouterr().out


def test_resolve_a_run_and_its_layers(tmp_path):
    run = tmp_path / "store" / "runs" / "r1"
    (run / "transfer_opt").mkdir(parents=True)
    _scene(run / "transfer_opt" / "scene.ply")
    (run / "point_cloud").mkdir()
    write_points(run / "point_cloud" / "pf.ply", np.zeros((3, 3)), np.zeros((3, 3), np.uint8))
    (tmp_path / "store" / "latest").symlink_to("runs/r1")
    for target in (None, "r1", str(run), str(run / "transfer_opt"), str(run / "transfer_opt" / "scene.ply")):
        assert view.resolve(target, tmp_path / "store").scene.name == "scene.ply", target
    assert set(view.resolve("r1", tmp_path / "store").extras) == {"P_f"}
    with pytest.raises(view.ViewError, match="has no pre_opt/gaussians.ply"):
        view.resolve("pre_opt", tmp_path / "store")
    with pytest.raises(view.ViewError, match="is not a file, a run, or a stage"):
        view.resolve("r2", tmp_path / "store")
    with pytest.raises(view.ViewError, match="no run in the store"):
        view.resolve(None, tmp_path / "empty")


def test_not_a_scene_is_one_line(tmp_path, capsys):
    points = tmp_path / "pf.ply"
    write_points(points, np.zeros((3, 3)), np.zeros((3, 3), np.uint8))
    (tmp_path / "notes.txt").write_text("hello\n")
    for target in (points, tmp_path / "notes.txt"):
        assert view.main([str(target), "--port", "0"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "not a 3DGS scene" in err, err


def test_port_in_use_is_one_line(tmp_path, capsys):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert view.main([str(_scene(tmp_path / "s.ply")), "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"port {port} on 127.0.0.1 is in use" in err, err


def test_look_around_turns_once_level_from_the_centre():
    class Client:
        """Records the camera after each atomic update, as viser's client handle would send it."""

        def __init__(self):
            self.camera, self.frames = SimpleNamespace(), []

        @contextmanager
        def atomic(self):
            yield
            self.frames.append((self.camera.position, self.camera.look_at, self.camera.up_direction))

    client = Client()
    view.look_around(client, seconds=0.0, steps=8)
    assert len(client.frames) == 9
    assert all(pos == (0, 0, 0) and up == (0, -1, 0) and at[1] == 0 for pos, at, up in client.frames)
    looks = np.array([at for _, at, _ in client.frames])
    np.testing.assert_allclose(
        looks[[0, 2, 4, 6, 8]], [[0, 0, 1], [1, 0, 0], [0, 0, -1], [-1, 0, 0], [0, 0, 1]], atol=1e-12
    )  # forward, right (+x), back, left, forward

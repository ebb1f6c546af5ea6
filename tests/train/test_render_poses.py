"""``fusiongs render --poses``: novel views of a finished run from camera poses of one's own."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fusiongs.camera.tum import PoseSamples, read_tum, write_tum
from fusiongs.cli import main
from fusiongs.frames.image_io import read_image
from fusiongs.train.restore import restore_state


@pytest.fixture(scope="module")
def restored(tiny_run):
    return restore_state(tiny_run / "checkpoint.pt")


def test_render_poses_equals_render_at_the_instants_of_those_poses(restored):
    # The same view matrices two ways: the fitted path's poses handed back as poses.
    state, camera, _ = restored
    t = torch.tensor([0.02, 0.05, 0.09], dtype=torch.float64)
    with torch.no_grad():
        c2w = state.trajectory.c2w(t)
        a, alpha_a, _ = state.render(camera, t)
        b, alpha_b, _ = state.render_poses(camera, c2w)
    assert b.shape == (3, camera.height, camera.width, 3)
    torch.testing.assert_close(b, a, rtol=0, atol=1e-6)
    torch.testing.assert_close(alpha_b, alpha_a, rtol=0, atol=1e-6)


def test_a_moved_camera_sees_the_scene_moved(restored):
    # A camera moved along its own x axis (right, OpenCV axes) sees the scene move left in the image:
    # the new image at column x looks like the old one at x + s for some s > 0, not s <= 0.
    state, camera, _ = restored
    with torch.no_grad():
        c2w = state.trajectory.c2w(torch.tensor([0.05], dtype=torch.float64))
        right = c2w.clone()
        right[:, :3, 3] += 0.5 * c2w[:, :3, 0]
        a, _, _ = state.render_poses(camera, c2w)
        b, _, _ = state.render_poses(camera, right)
    grey_a, grey_b = a[0].mean(-1), b[0].mean(-1)
    w = grey_a.shape[1]

    def mismatch(s):  # mean |b(x) - a(x + s)| over the columns both hold
        lo, hi = max(0, s), max(0, -s)
        return float((grey_b[:, hi: w - lo] - grey_a[:, lo: w - hi]).abs().mean())
    errs = {s: mismatch(s) for s in range(-6, 7)}
    assert min(errs, key=errs.get) > 0, errs


def test_the_command_writes_one_image_per_pose_and_a_video(tiny_run, tmp_path, capsys):
    path = tmp_path / "poses.txt"
    fitted = read_tum(tiny_run / "trajectory.txt")
    pick = np.linspace(0, len(fitted) - 1, 3).round().astype(int)
    write_tum(path, PoseSamples(fitted.t[pick], fitted.c2w[pick]))
    out = tmp_path / "out"
    assert main(["render", str(tiny_run), "--poses", str(path), "-o", str(out), "--video", "--fps", "5"]) == 0
    files = sorted(out.glob("pose_*.png"))
    assert [f.name for f in files] == [f"pose_{t:.6f}.png" for t in fitted.t[pick]]
    assert (out / "renders.mp4").stat().st_size > 0
    # the fitted path's own poses give the images `--t` gives at their instants (8-bit, 9 decimals)
    assert main(["render", str(tiny_run), "--t", *(repr(float(t)) for t in fitted.t[pick[1:2]]),
                 "-o", str(tmp_path / "t")]) == 0
    by_t = read_image(next((tmp_path / "t").glob("t_*.png")))
    assert np.abs(read_image(files[1]) - by_t).max() <= 1.5 / 255


@pytest.mark.parametrize("text, words", [
    ("0 0 0 0 0 0 0\n", ["poses.txt", "line 1", "8 finite numbers"]),
    ("0 0 0 0 0 0 0 2\n", ["poses.txt", "line 1", "unit quaternion"]),
    ("# nothing\n", ["poses.txt", "at least one pose"]),
])
def test_a_bad_poses_file_is_one_line_and_exit_2(tiny_run, tmp_path, capsys, text, words):
    path = tmp_path / "poses.txt"
    path.write_text(text)
    assert main(["render", str(tiny_run), "--poses", str(path), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err
    assert not (tmp_path / "o").exists()


def test_fps_must_be_positive_and_t_and_poses_exclude_each_other(tiny_run, tmp_path, capsys):
    assert main(["render", str(tiny_run), "--t", "0.05", "--video", "--fps", "0", "-o", str(tmp_path)]) == 2
    assert "--fps" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["render", str(tiny_run), "--t", "0.05", "--poses", str(tmp_path / "p.txt")])
    assert e.value.code == 2


def test_scale_renders_the_same_view_at_more_pixels(tiny_run, tmp_path, capsys):
    assert main(["render", str(tiny_run), "--t", "0.05", "-o", str(tmp_path / "x1")]) == 0
    assert main(["render", str(tiny_run), "--t", "0.05", "--scale", "2", "-o", str(tmp_path / "x2")]) == 0
    one = read_image(next((tmp_path / "x1").glob("t_*.png")))
    two = read_image(next((tmp_path / "x2").glob("t_*.png")))
    h, w = one.shape[:2]
    assert two.shape == (2 * h, 2 * w, 3)
    pooled = two.reshape(h, 2, w, 2, 3).mean((1, 3))  # 2x2 blocks (in sRGB: close enough here)
    assert np.abs(pooled - one).mean() < 0.005
    shifted = np.roll(pooled, 2, axis=1)  # a view moved by 2 px matches worse: the test can fail
    assert np.abs(shifted - one).mean() > np.abs(pooled - one).mean()
    for bad in ("0", "-1", "9", "nan"):
        assert main(["render", str(tiny_run), "--t", "0.05", "--scale", bad, "-o", str(tmp_path / "b")]) == 2
        assert "--scale" in capsys.readouterr().err


def test_depth_from_poses_of_a_plane_of_gaussians():
    # Gaussians on the plane z = 3 seen from the origin, then from a camera moved back by 1 along
    # its z axis (and one turned away, which sees nothing: NaN, not a number made up).
    from fusiongs.camera.pinhole import PinholeCamera
    from fusiongs.camera.trajectory import Trajectory
    from fusiongs.losses.threshold import ContrastThreshold
    from fusiongs.scene.gaussians import GaussianModel
    from fusiongs.train.render_io import render_depth_maps
    from fusiongs.train.state import FusionState

    cam = PinholeCamera(width=24, height=16, fx=20.0, fy=20.0, cx=12.0, cy=8.0)
    xy = torch.stack(torch.meshgrid(torch.linspace(-3, 3, 31), torch.linspace(-3, 3, 31), indexing="ij"), -1)
    model = GaussianModel.from_points(torch.cat([xy.reshape(-1, 2), torch.full((961, 1), 3.0)], 1),
                                      sh_degree=0, init_opacity=0.95)
    traj = Trajectory(PoseSamples(t=np.array([0.0, 1.0]), c2w=np.tile(np.eye(4), (2, 1, 1))), mode="linear")
    state = FusionState(model, traj, ContrastThreshold(), 1, False)
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[1, 2, 3] = -1.0  # moved back: the plane is 4 away
    poses[2, :3, :3] = np.diag([-1.0, 1.0, -1.0])  # turned around (a rotation about y by pi)
    depth = render_depth_maps(state, cam, [0, 1, 2], poses=poses)
    assert depth.shape == (3, 16, 24) and depth.dtype == np.float32
    for k, expect in ((0, 3.0), (1, 4.0)):
        seen = np.isfinite(depth[k])
        assert seen.mean() > 0.9
        np.testing.assert_allclose(depth[k][seen], expect, rtol=1e-3)
    assert np.isnan(depth[2]).all()
    # the same through the trajectory at t = 0 (the identity pose)
    np.testing.assert_allclose(render_depth_maps(state, cam, [0.0])[0], depth[0], rtol=1e-6)


def test_the_command_writes_depth_maps_beside_the_images(tiny_run, tmp_path):
    out = tmp_path / "d"
    assert main(["render", str(tiny_run), "--t", "0.05", "--depth", "-o", str(out)]) == 0
    img = read_image(next(out.glob("t_*.png")))
    depth = np.load(next(out.glob("t_*_depth.npy")))
    assert depth.shape == img.shape[:2] and depth.dtype == np.float32
    seen = np.isfinite(depth)
    assert seen.mean() > 0.5 and (depth[seen] > 0).all()


def test_poses_whose_times_name_the_same_image_are_refused(tiny_run, tmp_path, capsys):
    fitted = read_tum(tiny_run / "trajectory.txt")
    path = tmp_path / "poses.txt"
    write_tum(path, PoseSamples(np.array([0.1, 0.1000001]), fitted.c2w[:2]))
    assert main(["render", str(tiny_run), "--poses", str(path), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "poses.txt: t: expected times that differ within 6 decimals" in err[0], err
    assert not (tmp_path / "o").exists()
    # the same instant twice is the same image, as before
    assert main(["render", str(tiny_run), "--t", "0.05", "0.05", "-o", str(tmp_path / "same")]) == 0

"""Rollout videos: real MuJoCo offscreen rendering (EGL) of a walking robot, written as MP4."""

import imageio.v2 as imageio
import numpy as np
import pytest

from hierloco.components.expert_library import build_expert_library
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.render import render_frames, save_video


@pytest.fixture(scope="module")
def walking_qpos():
    library = build_expert_library("daisy", 1, seed=0, progress=False)
    sim = BatchedSimulator("daisy", 1)
    return sim.run(np.tile(library.joint_targets, (1, 2, 1))).qpos[0, ::10]  # 20 frames over 2 s


def test_frames_show_the_robot_moving(walking_qpos):
    frames = render_frames("daisy", walking_qpos, width=160, height=120)
    assert frames.shape == (len(walking_qpos), 120, 160, 3) and frames.dtype == np.uint8
    assert frames.std() > 10, "not a blank image"
    # legs move between frames (the camera follows the body, so the image changes only through the robot/floor)
    assert np.abs(frames[0].astype(int) - frames[5].astype(int)).mean() > 1.0


def test_markers_are_drawn(walking_qpos):
    plain = render_frames("daisy", walking_qpos[:1], width=160, height=120)
    marked = render_frames("daisy", walking_qpos[:1], width=160, height=120, markers=np.array([[0.5, 0.5]]))
    assert np.abs(plain.astype(int) - marked.astype(int)).sum() > 0


def test_video_round_trip(walking_qpos, tmp_path):
    frames = render_frames("daisy", walking_qpos, width=160, height=120)
    path = tmp_path / "walk.mp4"
    save_video(frames, path, fps=10)
    back = imageio.mimread(path, format="FFMPEG")
    assert len(back) == len(frames) and back[0].shape == frames[0].shape
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walk.mp4"]


def test_bad_input_is_refused(walking_qpos, tmp_path):
    with pytest.raises(ValueError, match="qpos must be"):
        render_frames("daisy", walking_qpos[:, :5])
    with pytest.raises(ValueError, match="uint8"):
        save_video(np.zeros((2, 8, 8, 3)), tmp_path / "x.mp4")


def test_camera_follows_the_robot(walking_qpos):
    """Far from the origin the robot is still in the middle of the picture: its pixels differ from an empty floor."""
    far = walking_qpos[:1].copy()
    far[0, :2] += [5.0, -3.0]
    frames = render_frames("daisy", np.concatenate([walking_qpos[:1], far]), width=160, height=120)
    centre = (slice(40, 80), slice(55, 105))
    np.testing.assert_allclose(frames[1][centre].mean(), frames[0][centre].mean(), atol=12)
    assert frames[1][centre].std() > 15, "the robot, not bare floor, is in the centre of the picture"

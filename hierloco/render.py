"""Rollout videos: MuJoCo offscreen rendering (EGL on Mesa by default) of recorded generalised positions.

Example:
    >>> import numpy as np, tempfile, os
    >>> from hierloco.envs.batched_sim import BatchedSimulator
    >>> sim = BatchedSimulator("a1", 1)
    >>> out = sim.run(np.tile(np.asarray(sim.robot.standing_pose), (1, 20, 1)))
    >>> frames = render_frames("a1", out.qpos[0], width=160, height=120)  # T x H x W x 3, uint8
    >>> frames.shape
    (20, 120, 160, 3)
    >>> save_video(frames, os.path.join(tempfile.mkdtemp(), "stand.mp4"), fps=25)
"""

from __future__ import annotations

import os
from typing import Sequence

import mujoco
import numpy as np

from hierloco.envs.robots import RobotSpec, compile_model, get_robot
from hierloco.io import atomic_path


def render_frames(robot: str | RobotSpec, qpos: np.ndarray, *, width: int = 320, height: int = 240,
                  distance: float | None = None, elevation: float = -25.0, azimuth: float = 135.0,
                  disabled_legs: Sequence[str] = (), markers: np.ndarray | None = None,
                  obstacles: Sequence = (), terrain=None) -> np.ndarray:
    """Renders ``T x nq`` generalised positions with a camera tracking the base; returns ``T x H x W x 3`` uint8.

    ``markers`` (``M x 2``, world-frame XY in m) draws small spheres on the ground, e.g. goals or a path.
    ``terrain`` is the ground the positions were simulated on (a name, a mapping of options or a built
    :class:`hierloco.envs.terrain.Terrain`, ``docs/terrain.md``; default flat): it is drawn, and the markers and
    obstacles stand on it.
    """
    from hierloco.envs.terrain import make_terrain

    robot = get_robot(robot)
    terrain = make_terrain(terrain)
    model = compile_model(robot, disabled_legs, obstacles, terrain=terrain)
    qpos = np.asarray(qpos, dtype=np.float64)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise ValueError(f"qpos must be T x {model.nq} for {robot.name}, got {qpos.shape}")
    model.vis.headlight.ambient[:] = 0.35
    model.vis.headlight.diffuse[:] = 0.6
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    data = mujoco.MjData(model)
    base = model.body(robot.base_body).id
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE  # looking at the base, moved with it every frame
    camera.distance = distance if distance is not None else 6.0 * robot.standing_height + 0.5
    camera.elevation, camera.azimuth = elevation, azimuth
    frames = np.empty((len(qpos), height, width, 3), dtype=np.uint8)
    with mujoco.Renderer(model, height, width) as renderer:
        for t, q in enumerate(qpos):
            data.qpos[:] = q
            mujoco.mj_kinematics(model, data)
            camera.lookat[:] = data.xpos[base]
            renderer.update_scene(data, camera=camera)
            if markers is not None:
                _add_markers(renderer.scene, np.asarray(markers), terrain)
            frames[t] = renderer.render()
    return frames


def _add_markers(scene: mujoco.MjvScene, points: np.ndarray, terrain=None) -> None:
    points = points[: max(0, scene.maxgeom - scene.ngeom)]
    ground = (np.maximum(terrain.height_at(points[:, 0], points[:, 1]), 0.0) if terrain is not None and len(points)
              else np.zeros(len(points)))
    for (x, y), z in zip(points, ground):
        mujoco.mjv_initGeom(scene.geoms[scene.ngeom], mujoco.mjtGeom.mjGEOM_SPHERE, np.array([0.03, 0, 0]),
                            np.array([x, y, z + 0.03]), np.eye(3).ravel(), np.array([1.0, 0.8, 0.1, 1.0], np.float32))
        scene.ngeom += 1


def render_terrain(terrain, robot: str | RobotSpec = "a1", *, width: int = 480, height: int = 360,
                   distance: float = 6.0, elevation: float = -30.0, azimuth: float = 135.0) -> np.ndarray:
    """One picture (``H x W x 3`` uint8) of a terrain (a name, a mapping of options or a built
    :class:`hierloco.envs.terrain.Terrain`) from above at an angle, looking at the start, with ``robot`` standing
    there for scale (``docs/terrain.md``)."""
    from hierloco.envs.terrain import make_terrain, standing_qpos_on

    robot = get_robot(robot)
    terrain = make_terrain(terrain)
    model = compile_model(robot, terrain=terrain)
    qpos = standing_qpos_on(terrain, model, robot)
    return render_frames(robot, qpos[None], width=width, height=height, distance=distance, elevation=elevation,
                         azimuth=azimuth, terrain=terrain)[0]


def save_video(frames: np.ndarray, path: str | os.PathLike, fps: int = 25) -> None:
    """Writes ``T x H x W x 3`` uint8 frames to an MP4 (H.264, via imageio-ffmpeg) atomically."""
    import imageio.v2 as imageio

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames must be T x H x W x 3 uint8, got {frames.shape} {frames.dtype}")
    with atomic_path(path) as tmp:
        with imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264", macro_block_size=8,
                                ffmpeg_log_level="error") as writer:
            for frame in frames:
                writer.append_data(frame)

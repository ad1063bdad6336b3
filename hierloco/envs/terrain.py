"""The world off the lab floor: terrain, pushes and randomised dynamics (``docs/terrain.md``).

**Terrain** is a part of the world, chosen by name from the registry :data:`TERRAINS` (like tasks and planners),
with keyword options; ``flat`` is the default and leaves the robot's model exactly as it was. The built-in
terrains take a ``difficulty`` in [0, 1] mapped linearly to one physical size (an explicit size option overrides
it) and are generated procedurally from ``seed``:

============  ==========================================================  =======================================
name          the ground                                                   difficulty 1 means
============  ==========================================================  =======================================
``flat``      the floor plane (nothing added)                              -
``rough``     a random heightfield, heights uniform in [0, amplitude]     ``amplitude_m`` = 0.10 m
``slope``     ramps up then down at ``angle_rad``, in rings about the      ``angle_rad`` = 0.40 rad (23 deg)
              start (a heightfield)
``stairs``    square flights of steps up, then down, about the start      ``step_height_m`` = 0.20 m
``blocks``    random rectangular blocks, heights in [h / 2, h]             ``height_m`` = 0.20 m
``slippery``  patches of low friction (2 mm thick) on the floor           ``friction`` = 0.1 (1.0 at 0)
``heightmap`` a user's heightfield image (PNG, white = ``height_m``)       -
``mjcf``      a user's MJCF file whose world geoms form the ground         -
============  ==========================================================  =======================================

A terrain adds its geoms to a :class:`mujoco.MjSpec` (:meth:`Terrain.add_to`, called by
:func:`hierloco.envs.robots.compile_model` with ``terrain=``) and answers :meth:`Terrain.height_at` (vectorised,
world frame, m), which is exact for what it built: the heightfields are interpolated as MuJoCo triangulates them,
boxes are boxes, an MJCF ground is ray-cast. Robots start with their lowest geom just above the local ground
(:func:`standing_qpos_on`); tasks keep their world frame (x, y); a robot has fallen when its base is lower than
its ``min_height`` above the lowest ground near it (:meth:`Terrain.ground_below`). The floor plane stays under
every built-in terrain (their heights are >= 0 and they end at the floor beyond ``extent_m``; under a heightfield
the floor lies 5 mm lower, :data:`FLOOR_DROP_M`).

**Pushes** (:class:`Pushes`): velocity impulses of ``magnitude_mps`` on the trunk at random times, given to the
batched simulator (:class:`hierloco.envs.batched_sim.BatchedSimulator`, ``pushes=``), which logs each one
(:class:`PushEvent`) so that an evaluation can count falls and the time to recover.

**Randomised dynamics** (:class:`DynamicsRandomization`): per simulated robot and episode, payload and CoM offset,
foot friction, motor strength (kp and torque limit), servo latency and joint damping, drawn from stated ranges
(``randomization=`` of the batched simulator; every copy gets a model of its own).

Every option is recorded: ``key()`` of a terrain, pushes or randomisation is the dict that enters a stage key, empty
for the defaults (flat, no pushes, nominal dynamics).

Example:
    >>> terrain = make_terrain("rough", difficulty=0.5, seed=1)
    >>> terrain.key()
    {'name': 'rough', 'difficulty': 0.5, 'seed': 1}
    >>> bool(0.0 <= terrain.height_at(0.3, -1.2) <= 0.05)  # amplitude 0.05 m at difficulty 0.5
    True
    >>> make_terrain("flat").key(), Pushes().key(), DynamicsRandomization().key()
    ({}, {}, {})
"""

from __future__ import annotations

import hashlib
import inspect
import math
import numbers
import os
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import mujoco
import numpy as np

from hierloco.envs.robots.spec import (
    CONTROL_TIMESTEP,
    PHYSICS_TIMESTEP,
    START_YAW,
    Obstacle,
    RobotSpec,
    _geom_bottom,
    standing_qpos,
)
from hierloco.registry import Registry, without_defaults

# The terrains by name (a ``terrain`` option): a new one is a :class:`Terrain` subclass decorated with
# ``@TERRAINS.register("name")``; its options are its constructor's keyword arguments. Installed packages add
# terrains through the entry-point group ``hierloco.terrains``; a user's ``package.module:Class`` is imported where
# the user names it (``TERRAINS.import_path``, as for every registry: hierloco/registry.py).
TERRAINS = Registry("terrain")

# difficulty 1 -> physical size (difficulty d gives d times these; docs/terrain.md)
ROUGH_MAX_AMPLITUDE_M = 0.10
SLOPE_MAX_ANGLE_RAD = 0.40
STAIRS_MAX_STEP_HEIGHT_M = 0.20
BLOCKS_MAX_HEIGHT_M = 0.20
SLIPPERY_FRICTION_RANGE = (1.0, 0.1)  # sliding friction at difficulty 0 and 1 (the floor's is 1.0)

START_CLEARANCE_M = 0.002  # the robot's lowest geom starts this far above the highest ground under it
PATCH_THICKNESS_M = 0.002  # slippery patches lie on the floor, this thick
HFIELD_BASE_M = 0.05  # depth of a heightfield's base below z = 0
FLOOR_DROP_M = 0.005  # under a heightfield the floor plane lies this much lower, so that where the heightfield is at
# 0 m the feet stand on it alone (not on it and on the plane at once: twice the contacts)
GROUND_FRICTION = (1.0, 0.005, 0.0001)  # sliding, torsional, rolling: the floor's (robots/spec.py)
GROUND_RGBA = (0.45, 0.5, 0.55, 1.0)
TERRAIN_PREFIX = "terrain_"


class TerrainError(ValueError):
    """A bad terrain: an unknown name, a bad option, a missing or malformed terrain file (one line)."""


# ---------------------------------------------------------------------------------------------------- checks
def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _real(where: str, name: str, value, *, low: float | None = None, high: float | None = None,
          positive: bool = False) -> float:
    """``value`` as a finite float in ``[low, high]`` (``> 0`` with ``positive``), or a :class:`TerrainError`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise TerrainError(f"{where}: {name} must be a finite number, got {value!r}")
    value = float(value)
    if positive and not value > 0:
        raise TerrainError(f"{where}: {name} must be positive, got {value!r}")
    if (low is not None and value < low) or (high is not None and value > high):
        raise TerrainError(f"{where}: {name} must be in [{low}, {high}], got {value!r}")
    return value


def _whole(where: str, name: str, value, *, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise TerrainError(f"{where}: {name} must be a whole number >= {low}, got {value!r}")
    return int(value)


def _range(where: str, name: str, value, *, low: float, high: float, whole: bool = False) -> tuple:
    """A ``(lo, hi)`` pair with ``low <= lo <= hi <= high``, or a :class:`TerrainError`."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise TerrainError(f"{where}: {name} must be a (low, high) pair, got {value!r}")
    if whole:
        lo, hi = (_whole(where, name, v, low=int(low)) for v in value)
        if hi > high:
            raise TerrainError(f"{where}: {name} must be within [{low}, {high}], got {value!r}")
    else:
        lo, hi = (_real(where, name, v, low=low, high=high) for v in value)
    if lo > hi:
        raise TerrainError(f"{where}: {name} low {lo} exceeds high {hi}")
    return (lo, hi)


def _keyword_defaults(cls) -> dict[str, Any]:
    """A class's options: its constructor's keyword arguments with defaults, in order."""
    return {p.name: p.default for p in inspect.signature(cls.__init__).parameters.values()
            if p.name != "self" and p.default is not p.empty and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)}


def _xy(x_m, y_m) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    return x, y


# ---------------------------------------------------------------------------------------------------- base class
class Terrain:
    """The ground of the world. Subclasses add geoms to a model and answer heights.

    A subclass registered with ``@TERRAINS.register(name)`` takes keyword options with defaults, keeps each under
    its own name (``self.<option>``, for :meth:`key`) and implements :meth:`add_to` and :meth:`height_at`.
    Heights are in m, world frame; ``x, y`` beyond the terrain are on the floor (0 m; 5 mm lower beside a
    heightfield).

    Attributes:
        seeded: whether ``seed`` changes the terrain (else it is left out of the key).
        is_flat: the floor alone: nothing is added and every simulator runs as without a terrain.
    """

    registry_name = "terrain"
    seeded = False
    is_flat = False

    def add_to(self, spec: mujoco.MjSpec) -> None:
        """Adds this terrain's assets and geoms to ``spec``'s world (after the floor is there)."""
        raise NotImplementedError

    def height_at(self, x_m, y_m) -> np.ndarray:
        """The ground's height in m at world points ``(x_m, y_m)`` (arrays broadcast together; same shape out)."""
        raise NotImplementedError

    # -------------------------------------------------------------------------------------- derived
    def ground_below(self, x_m, y_m, reach_m: float = 0.0) -> np.ndarray:
        """The lowest ground (m) at ``(x_m, y_m)`` and at the four points ``reach_m`` away along the world axes: what
        a robot's height is measured from when it is judged fallen (a base over a step's edge has not fallen)."""
        x, y = _xy(x_m, y_m)
        lowest = self.height_at(x, y)
        if reach_m > 0:
            for dx, dy in ((reach_m, 0.0), (-reach_m, 0.0), (0.0, reach_m), (0.0, -reach_m)):
                lowest = np.minimum(lowest, self.height_at(x + dx, y + dy))
        return lowest

    def highest_in_disc(self, x_m: float, y_m: float, radius_m: float) -> float:
        """The highest ground (m) sampled in a disc (centre, 3 rings of 16 points, a 0.01 m grid for discs up to
        0.1 m radius): where a geom of that footprint must stand clear of."""
        angles = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
        radii = np.array([radius_m / 3, 2 * radius_m / 3, radius_m])
        xs = [np.array([x_m]), (x_m + radii[:, None] * np.cos(angles)).ravel()]
        ys = [np.array([y_m]), (y_m + radii[:, None] * np.sin(angles)).ravel()]
        if 0 < radius_m <= 0.1:
            grid = np.arange(-radius_m, radius_m + 1e-12, 0.01)
            gx, gy = np.meshgrid(grid, grid)
            inside = gx ** 2 + gy ** 2 <= radius_m ** 2
            xs.append(x_m + gx[inside])
            ys.append(y_m + gy[inside])
        return float(np.max(self.height_at(np.concatenate(xs), np.concatenate(ys))))

    def place_obstacles(self, obstacles: Sequence[Obstacle]) -> tuple[Obstacle, ...]:
        """Static boxes (a navigation arena) standing on this ground: each reaches from the floor (z = 0) to its own
        height above the highest ground under its footprint. Flat ground: the boxes unchanged."""
        placed = []
        for obstacle in obstacles:
            hx, hy, hz = obstacle.half_size
            c, s = math.cos(obstacle.yaw), math.sin(obstacle.yaw)
            u, v = np.meshgrid(np.linspace(-hx, hx, 9), np.linspace(-hy, hy, 9))
            ground = float(np.max(self.height_at(obstacle.x + c * u - s * v, obstacle.y + s * u + c * v)))
            ground = max(ground, 0.0)
            placed.append(Obstacle(obstacle.x, obstacle.y, (hx, hy, hz + ground / 2), obstacle.yaw))
        return tuple(placed)

    # -------------------------------------------------------------------------------------- options
    @classmethod
    def _defaults(cls) -> dict[str, Any]:
        return _keyword_defaults(cls)

    def options(self) -> dict[str, Any]:
        """The options this terrain was made with (defaults filled in)."""
        return {name: getattr(self, name) for name in self._defaults()}

    def key(self) -> dict[str, Any]:
        """What enters a stage key: ``{}`` for flat ground; else the name, ``difficulty`` and ``seed`` (when they
        apply) and every other option that differs from its default (a file's path is replaced by the sha256 of
        its bytes, so that a moved file keeps its keys and an edited one changes them)."""
        if self.is_flat:
            return {}
        options = self.options()
        if not self.seeded:
            options.pop("seed", None)
        key = without_defaults(options, self._defaults(), keep=("difficulty", "seed"))
        if "path" in key:
            key.pop("path")
            key["sha256"] = self.file_digest
        key = {name: list(value) if isinstance(value, tuple) else value for name, value in key.items()}
        return {"name": self.registry_name, **key}

    def describe(self) -> str:
        """One line for reports: ``"rough (difficulty=0.5, seed=1)"``."""
        key = self.key()
        if not key:
            return "flat"
        name = key.pop("name")
        return f"{name} ({', '.join(f'{k}={v}' for k, v in key.items())})" if key else name

    def __repr__(self) -> str:
        return f"<terrain {self.describe()}>"


@TERRAINS.register("flat")
class Flat(Terrain):
    """The floor plane alone: adds nothing, so models, states and keys are those of hierloco without terrain."""

    is_flat = True

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0):
        self.difficulty = _difficulty("terrain 'flat'", difficulty)  # accepted (a sweep over difficulties), not used
        self.seed = _whole("terrain 'flat'", "seed", seed)

    def add_to(self, spec: mujoco.MjSpec) -> None:
        return None

    def height_at(self, x_m, y_m) -> np.ndarray:
        x, _ = _xy(x_m, y_m)
        return np.zeros(x.shape)

    def place_obstacles(self, obstacles: Sequence[Obstacle]) -> tuple[Obstacle, ...]:
        return tuple(obstacles)


# ---------------------------------------------------------------------------------------------------- heightfields
class HeightfieldTerrain(Terrain):
    """A ground given as heights on a regular grid (a MuJoCo ``hfield``), centred at ``centre_m``.

    Subclasses set ``self._set_grid(heights_m, half_extent_m)``: ``heights_m`` is ``nrow x ncol``, row ``r`` at
    ``y = cy - hy + 2 hy r / (nrow - 1)``, column ``c`` at ``x = cx - hx + 2 hx c / (ncol - 1)``, all >= 0. MuJoCo
    stores the heights as float32 fractions of their range (the geom sits at the lowest, its base reaches below the
    floor); :meth:`height_at` uses exactly those, and its
    triangles: each cell is split along the diagonal from ``(r, c)`` to ``(r + 1, c + 1)``. The floor plane is moved
    :data:`FLOOR_DROP_M` down (beyond the heightfield the ground is at ``-FLOOR_DROP_M``).
    """

    centre_m = (0.0, 0.0)

    def _set_grid(self, heights_m: np.ndarray, half_extent_m: tuple[float, float]) -> None:
        heights = np.asarray(heights_m, dtype=np.float64)
        if heights.ndim != 2 or min(heights.shape) < 2 or not np.all(np.isfinite(heights)) or heights.min() < 0:
            raise TerrainError(f"terrain {self.registry_name!r}: heights must be a grid of at least 2 x 2 finite "
                               "numbers >= 0 m")
        self._bottom = float(heights.min())
        spread = float(heights.max()) - self._bottom
        self._range = spread if spread > 0 else 1e-6  # MuJoCo needs a positive elevation
        self._fraction = ((heights - self._bottom) / self._range).astype(np.float32)  # MuJoCo's own normalisation
        self._heights = self._bottom + self._fraction.astype(np.float64) * self._range
        self._half_extent = (float(half_extent_m[0]), float(half_extent_m[1]))

    def add_to(self, spec: mujoco.MjSpec) -> None:
        for geom in spec.worldbody.geoms:
            if geom.type == mujoco.mjtGeom.mjGEOM_PLANE:
                geom.pos = [geom.pos[0], geom.pos[1], geom.pos[2] - FLOOR_DROP_M]
        nrow, ncol = self._fraction.shape
        name = f"{TERRAIN_PREFIX}{self.registry_name}"
        spec.add_hfield(name=name, nrow=nrow, ncol=ncol,
                        size=[self._half_extent[0], self._half_extent[1], self._range, self._bottom + HFIELD_BASE_M],
                        userdata=self._fraction.ravel().tolist())
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=name,
                                pos=[self.centre_m[0], self.centre_m[1], self._bottom],
                                friction=list(GROUND_FRICTION),
                                rgba=list(GROUND_RGBA), contype=1, conaffinity=1)

    def height_at(self, x_m, y_m) -> np.ndarray:
        x, y = _xy(x_m, y_m)
        (hx, hy), (cx, cy) = self._half_extent, self.centre_m
        nrow, ncol = self._heights.shape
        u = (x - cx + hx) / (2 * hx) * (ncol - 1)
        v = (y - cy + hy) / (2 * hy) * (nrow - 1)
        inside = (u >= 0) & (u <= ncol - 1) & (v >= 0) & (v <= nrow - 1)
        c = np.clip(np.floor(u), 0, ncol - 2).astype(np.int64)
        r = np.clip(np.floor(v), 0, nrow - 2).astype(np.int64)
        fx, fy = np.clip(u - c, 0.0, 1.0), np.clip(v - r, 0.0, 1.0)
        h = self._heights
        h00, h01, h10, h11 = h[r, c], h[r, c + 1], h[r + 1, c], h[r + 1, c + 1]
        below_diagonal = fx >= fy
        z = np.where(below_diagonal, h00 + fx * (h01 - h00) + fy * (h11 - h01),
                     h00 + fy * (h10 - h00) + fx * (h11 - h10))
        return np.where(inside, z, -FLOOR_DROP_M)


def _square_grid(where: str, extent_m, resolution_m) -> tuple[float, float, int]:
    extent = _real(where, "extent_m", extent_m, positive=True)
    resolution = _real(where, "resolution_m", resolution_m, positive=True)
    points = int(round(2 * extent / resolution)) + 1
    if points < 3 or points > 2001:
        raise TerrainError(f"{where}: extent_m / resolution_m gives {points} grid points per side; keep it within "
                           "3 to 2001")
    return extent, resolution, points


def _difficulty(where: str, value) -> float:
    return _real(where, "difficulty", value, low=0.0, high=1.0)


@TERRAINS.register("rough")
class Rough(HeightfieldTerrain):
    """Random rough ground: a heightfield of ``(2 extent_m / resolution_m + 1)^2`` heights drawn uniformly in
    ``[0, amplitude_m]`` (the outer ring at 0 m, meeting the floor).

    Args:
        difficulty: in [0, 1]; the amplitude is ``difficulty * 0.10`` m unless ``amplitude_m`` is given.
        seed: draws the heights.
        amplitude_m: the highest a grid point may be, m (overrides ``difficulty``).
        resolution_m: grid spacing, m (0.2 m: legged_gym's rough ground draws its heights on a 0.2 m grid; a finer
            grid costs simulation speed, ``docs/terrain.md``).
        extent_m: half the side of the square of rough ground, centred at the origin, m.
    """

    seeded = True

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0, amplitude_m: float | None = None,
                 resolution_m: float = 0.2, extent_m: float = 5.0):
        where = "terrain 'rough'"
        self.difficulty = _difficulty(where, difficulty)
        self.seed = _whole(where, "seed", seed)
        self.amplitude_m = None if amplitude_m is None else _real(where, "amplitude_m", amplitude_m, low=0.0,
                                                                  high=1.0)
        self.resolution_m, self.extent_m = resolution_m, extent_m
        extent, _, points = _square_grid(where, extent_m, resolution_m)
        amplitude = self.difficulty * ROUGH_MAX_AMPLITUDE_M if self.amplitude_m is None else self.amplitude_m
        heights = np.random.default_rng(self.seed).uniform(0.0, amplitude, (points, points))
        heights[[0, -1], :] = 0.0
        heights[:, [0, -1]] = 0.0
        self._set_grid(heights, (extent, extent))


@TERRAINS.register("slope")
class Slope(HeightfieldTerrain):
    """Slopes up and down: beyond a flat start of radius ``platform_m``, the ground rises at ``angle_rad`` for
    ``run_m`` (horizontally), falls back to the floor over the next ``run_m``, and again, in rings about the origin
    for as many whole rings as fit in ``extent_m`` (so walking out in any direction climbs and descends the same
    slope). A heightfield sampled every ``resolution_m``.

    Args:
        difficulty: in [0, 1]; the angle is ``difficulty * 0.40`` rad unless ``angle_rad`` is given.
        angle_rad: the slope, rad (overrides ``difficulty``; below 1.2 rad).
        run_m: horizontal length of each ramp, m.
        platform_m: radius of the flat start, m.
        resolution_m, extent_m: grid spacing and half side of the heightfield, m.
        seed: not used (the slope is the same for every seed).
    """

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0, angle_rad: float | None = None,
                 run_m: float = 1.0, platform_m: float = 0.75, resolution_m: float = 0.1, extent_m: float = 5.0):
        where = "terrain 'slope'"
        self.difficulty = _difficulty(where, difficulty)
        self.seed = _whole(where, "seed", seed)
        self.angle_rad = None if angle_rad is None else _real(where, "angle_rad", angle_rad, low=0.0, high=1.2)
        self.run_m = _real(where, "run_m", run_m, positive=True)
        self.platform_m = _real(where, "platform_m", platform_m, low=0.0)
        self.resolution_m, self.extent_m = resolution_m, extent_m
        extent, resolution, points = _square_grid(where, extent_m, resolution_m)
        rings = int((extent - self.platform_m) // (2 * self.run_m))
        if rings < 1:
            raise TerrainError(f"{where}: no whole ring of slopes (2 run_m = {2 * self.run_m} m) fits between "
                               f"platform_m ({self.platform_m} m) and extent_m ({extent} m)")
        angle = self.difficulty * SLOPE_MAX_ANGLE_RAD if self.angle_rad is None else self.angle_rad
        axis = np.linspace(-extent, extent, points)
        x, y = np.meshgrid(axis, axis)
        s = np.hypot(x, y) - self.platform_m
        phase = np.mod(s, 2 * self.run_m)
        heights = math.tan(angle) * np.minimum(phase, 2 * self.run_m - phase)
        heights[(s < 0) | (s > rings * 2 * self.run_m)] = 0.0
        self._set_grid(heights, (extent, extent))


# ---------------------------------------------------------------------------------------------------- boxes
class BoxTerrain(Terrain):
    """A ground of axis-aligned boxes standing on the floor: ``self._boxes`` is ``K x 5`` rows ``(x, y, half_x,
    half_y, top_z)`` in m; each box reaches from z = 0 to ``top_z``. Boxes may overlap (the ground is the highest)."""

    _boxes = np.zeros((0, 5))
    box_friction = GROUND_FRICTION
    box_priority = 0
    box_rgba = (0.5, 0.5, 0.55, 1.0)

    def add_to(self, spec: mujoco.MjSpec) -> None:
        for i, (x, y, hx, hy, top) in enumerate(self._boxes):
            spec.worldbody.add_geom(name=f"{TERRAIN_PREFIX}{self.registry_name}_{i}", type=mujoco.mjtGeom.mjGEOM_BOX,
                                    size=[hx, hy, top / 2], pos=[x, y, top / 2], friction=list(self.box_friction),
                                    priority=self.box_priority, rgba=list(self.box_rgba), contype=1, conaffinity=1)

    def height_at(self, x_m, y_m) -> np.ndarray:
        x, y = _xy(x_m, y_m)
        height = np.zeros(x.shape)
        for bx, by, hx, hy, top in self._boxes:
            on = (np.abs(x - bx) <= hx) & (np.abs(y - by) <= hy)
            height = np.where(on, np.maximum(height, top), height)
        return height


def _square_ring(inner: float, outer: float, top: float) -> list[tuple[float, ...]]:
    """Four boxes covering ``inner <= max(|x|, |y|) <= outer`` (m), each ``top`` m high."""
    half, width = (outer + inner) / 2, (outer - inner) / 2
    return [(0.0, half, outer, width, top), (0.0, -half, outer, width, top),
            (half, 0.0, width, inner, top), (-half, 0.0, width, inner, top)]


@TERRAINS.register("stairs")
class Stairs(BoxTerrain):
    """Square flights of stairs about the start: beyond a flat platform (half side ``platform_m``) the ground
    climbs ``num_steps`` steps of ``step_height_m`` and ``step_depth_m``, then goes down as many back to the
    floor, in every direction (a square "pyramid" of steps, as legged_gym's). Boxes.

    Args:
        difficulty: in [0, 1]; the step height is ``difficulty * 0.20`` m unless ``step_height_m`` is given.
        step_height_m: the rise of each step, m (overrides ``difficulty``).
        step_depth_m: the tread of each step, m.
        num_steps: steps up (as many go down again).
        platform_m: half the side of the flat start, m.
        seed: not used (the stairs are the same for every seed).
    """

    box_rgba = (0.55, 0.5, 0.45, 1.0)

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0, step_height_m: float | None = None,
                 step_depth_m: float = 0.3, num_steps: int = 4, platform_m: float = 0.75):
        where = "terrain 'stairs'"
        self.difficulty = _difficulty(where, difficulty)
        self.seed = _whole(where, "seed", seed)
        self.step_height_m = None if step_height_m is None else _real(where, "step_height_m", step_height_m,
                                                                      low=0.0, high=1.0)
        self.step_depth_m = _real(where, "step_depth_m", step_depth_m, positive=True)
        self.num_steps = _whole(where, "num_steps", num_steps, low=1)
        self.platform_m = _real(where, "platform_m", platform_m, positive=True)
        rise = self.difficulty * STAIRS_MAX_STEP_HEIGHT_M if self.step_height_m is None else self.step_height_m
        boxes = []
        if rise > 0:
            for k in range(1, 2 * self.num_steps):  # rings 1..n up, n+1..2n-1 down (ring 2n is the floor)
                level = k if k <= self.num_steps else 2 * self.num_steps - k
                inner = self.platform_m + (k - 1) * self.step_depth_m
                boxes += _square_ring(inner, inner + self.step_depth_m, level * rise)
        self._boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)


@TERRAINS.register("blocks")
class Blocks(BoxTerrain):
    """Discrete obstacles: ``num_blocks`` rectangular blocks with sides uniform in ``[min_size_m, max_size_m]``
    and heights uniform in ``[height_m / 2, height_m]``, centred uniformly in the square of half side
    ``extent_m``; none reaches within ``clear_m`` (in x and y) of the start. Boxes.

    Args:
        difficulty: in [0, 1]; the block height is ``difficulty * 0.20`` m unless ``height_m`` is given.
        seed: draws the blocks.
        height_m: the tallest a block may be, m (overrides ``difficulty``).
        num_blocks, min_size_m, max_size_m, extent_m: how many blocks, their sides (m), where (m).
        clear_m: half side of the empty square about the start, m.
    """

    seeded = True
    box_rgba = (0.55, 0.45, 0.35, 1.0)

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0, height_m: float | None = None,
                 num_blocks: int = 40, min_size_m: float = 0.3, max_size_m: float = 0.8, extent_m: float = 4.0,
                 clear_m: float = 0.75):
        where = "terrain 'blocks'"
        self.difficulty = _difficulty(where, difficulty)
        self.seed = _whole(where, "seed", seed)
        self.height_m = None if height_m is None else _real(where, "height_m", height_m, low=0.0, high=2.0)
        self.num_blocks = _whole(where, "num_blocks", num_blocks)
        self.min_size_m = _real(where, "min_size_m", min_size_m, positive=True)
        self.max_size_m = _real(where, "max_size_m", max_size_m, positive=True)
        self.extent_m = _real(where, "extent_m", extent_m, positive=True)
        self.clear_m = _real(where, "clear_m", clear_m, low=0.0)
        if self.min_size_m > self.max_size_m:
            raise TerrainError(f"{where}: min_size_m {self.min_size_m} exceeds max_size_m {self.max_size_m}")
        if self.clear_m >= self.extent_m:
            raise TerrainError(f"{where}: clear_m ({self.clear_m} m) leaves no room within extent_m "
                               f"({self.extent_m} m)")
        height = self.difficulty * BLOCKS_MAX_HEIGHT_M if self.height_m is None else self.height_m
        rng = np.random.default_rng(self.seed)
        boxes, attempts = [], 0
        while len(boxes) < self.num_blocks and attempts < 1000 * max(1, self.num_blocks) and height > 0:
            attempts += 1
            hx, hy = rng.uniform(self.min_size_m, self.max_size_m, 2) / 2
            x, y = rng.uniform(-self.extent_m, self.extent_m, 2)
            top = rng.uniform(height / 2, height)
            if abs(x) - hx < self.clear_m and abs(y) - hy < self.clear_m:
                continue  # it reaches into the clear square about the start
            boxes.append((x, y, hx, hy, top))
        self._boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)


@TERRAINS.register("slippery")
class Slippery(BoxTerrain):
    """Patches of low friction: the floor split into ``patch_m`` squares over the square of half side
    ``extent_m``, each slippery with probability ``coverage``; a slippery square is a 2 mm thick patch whose
    sliding ``friction`` is the contact's, whatever the feet are made of (it takes priority).

    Args:
        difficulty: in [0, 1]; the patches' friction is ``1.0 - 0.9 difficulty`` unless ``friction`` is given.
        seed: draws which squares are slippery.
        friction: sliding friction coefficient of the patches (overrides ``difficulty``).
        coverage: the fraction of squares that are slippery (in expectation).
        patch_m, extent_m: side of a square and half side of the area, m.
    """

    seeded = True
    box_priority = 2  # above the feet's (robots/spec.py gives feet priority 1 when their friction is set)
    box_rgba = (0.6, 0.75, 0.9, 1.0)

    def __init__(self, *, difficulty: float = 0.5, seed: int = 0, friction: float | None = None,
                 coverage: float = 0.5, patch_m: float = 1.0, extent_m: float = 5.0):
        where = "terrain 'slippery'"
        self.difficulty = _difficulty(where, difficulty)
        self.seed = _whole(where, "seed", seed)
        self.friction = None if friction is None else _real(where, "friction", friction, positive=True, high=5.0)
        self.coverage = _real(where, "coverage", coverage, low=0.0, high=1.0)
        self.patch_m = _real(where, "patch_m", patch_m, positive=True)
        self.extent_m = _real(where, "extent_m", extent_m, positive=True)
        cells = int(round(2 * self.extent_m / self.patch_m))
        if not 1 <= cells <= 200:
            raise TerrainError(f"{where}: extent_m / patch_m gives {cells} squares per side; keep it within 1 to 200")
        high, low = SLIPPERY_FRICTION_RANGE
        mu = high + (low - high) * self.difficulty if self.friction is None else self.friction
        self.box_friction = (mu, GROUND_FRICTION[1], GROUND_FRICTION[2])
        slippery = np.random.default_rng(self.seed).random((cells, cells)) < self.coverage
        centres = -self.extent_m + self.patch_m * (np.arange(cells) + 0.5)
        rows, cols = np.nonzero(slippery)
        half = self.patch_m / 2
        self._boxes = np.array([(centres[c], centres[r], half, half, PATCH_THICKNESS_M) for r, c in zip(rows, cols)],
                               dtype=np.float64).reshape(-1, 5)

    def friction_at(self, x_m, y_m) -> np.ndarray:
        """The sliding friction of the ground at ``(x_m, y_m)``: the patches', else the floor's (1.0)."""
        x, y = _xy(x_m, y_m)
        on = self.height_at(x, y) > 0
        return np.where(on, self.box_friction[0], GROUND_FRICTION[0])


# ---------------------------------------------------------------------------------------------------- from files
class _FileTerrain(Terrain):
    """A terrain read from a file given by ``path``: checked and read when made (a missing or malformed file is a
    :class:`TerrainError` then, before any simulation); :attr:`file_digest` is the sha256 of its bytes."""

    def _read_path(self, where: str, path) -> str:
        if path is None or not isinstance(path, (str, os.PathLike)) or not str(path):
            raise TerrainError(f"{where}: give path= the terrain file")
        path = os.path.abspath(os.path.expanduser(os.fspath(path)))
        if not os.path.isfile(path):
            raise TerrainError(f"{where}: no terrain file {path}")
        with open(path, "rb") as handle:
            self.file_digest = hashlib.sha256(handle.read()).hexdigest()
        return path


@TERRAINS.register("heightmap")
class Heightmap(_FileTerrain, HeightfieldTerrain):
    """A user's heightfield image: a PNG seen from above (+x to the right, +y up: the top row of the image is the
    far +y edge), black at 0 m and white at ``height_m``, stretched over ``size_m`` (x, y) centred at the origin.
    Colour images are averaged over their RGB channels; an alpha channel is ignored.

    Args:
        path: the image file (read with matplotlib's ``imread``).
        size_m: the ground's (x, y) size, m.
        height_m: the height of white, m.
    """

    def __init__(self, *, path: str | None = None, size_m: tuple[float, float] = (8.0, 8.0), height_m: float = 0.2):
        where = "terrain 'heightmap'"
        self.path = self._read_path(where, path)
        if isinstance(size_m, (str, bytes)) or not isinstance(size_m, Sequence) or len(size_m) != 2:
            raise TerrainError(f"{where}: size_m must be an (x, y) pair of m, got {size_m!r}")
        self.size_m = tuple(_real(where, "size_m", v, positive=True) for v in size_m)
        self.height_m = _real(where, "height_m", height_m, low=0.0)
        from matplotlib import image as mpimg

        try:
            pixels = np.asarray(mpimg.imread(self.path))
        except Exception as error:  # PIL / matplotlib raise many kinds for a file that is not an image
            raise TerrainError(f"{where}: cannot read {self.path} as an image ({type(error).__name__}: "
                               f"{_one_line(error)})") from None
        if np.issubdtype(pixels.dtype, np.integer):
            pixels = pixels / float(np.iinfo(pixels.dtype).max)
        if pixels.ndim == 3:
            pixels = pixels[..., :3].mean(axis=-1)
        if pixels.ndim != 2 or min(pixels.shape) < 2:
            raise TerrainError(f"{where}: {self.path} is not an image of at least 2 x 2 pixels "
                               f"(shape {pixels.shape})")
        heights = np.clip(np.asarray(pixels, dtype=np.float64)[::-1], 0.0, 1.0) * self.height_m
        self._set_grid(heights, (self.size_m[0] / 2, self.size_m[1] / 2))


_MJCF_GEOM_TYPES = {mujoco.mjtGeom.mjGEOM_PLANE, mujoco.mjtGeom.mjGEOM_HFIELD, mujoco.mjtGeom.mjGEOM_SPHERE,
                    mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_ELLIPSOID, mujoco.mjtGeom.mjGEOM_CYLINDER,
                    mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_MESH}


@TERRAINS.register("mjcf")
class MjcfGround(_FileTerrain):
    """A user's MJCF file whose static geoms form the ground: every geom of the world body and of bodies welded to
    it (no joints), as a scene file many robot packages ship (its robot, which has joints, is left out). The file
    is compiled by MuJoCo (includes, defaults and asset paths resolved) and its geoms are copied in world
    coordinates with their contact parameters and colour (textures are not copied). When they include a plane, it
    replaces the floor. Heightfields keep their grid; meshes collide as their convex hulls, as always in MuJoCo.

    Args:
        path: the MJCF (XML) file.
    """

    def __init__(self, *, path: str | None = None):
        where = "terrain 'mjcf'"
        self.path = self._read_path(where, path)
        try:
            model = mujoco.MjSpec.from_file(self.path).compile()
        except Exception as error:  # MuJoCo's parser and compiler raise ValueError with several lines
            raise TerrainError(f"{where}: cannot load {self.path} ({_one_line(error)})") from None
        self._geoms = _static_geoms(model, where, self.path)
        self._has_plane = any(g["type"] == mujoco.mjtGeom.mjGEOM_PLANE for g in self._geoms)
        spec = mujoco.MjSpec()
        _add_geoms(spec, [g for g in self._geoms if g["contype"] or g["conaffinity"]], rays=True)
        self._ray_model = spec.compile()
        self._ray_data = mujoco.MjData(self._ray_model)
        mujoco.mj_kinematics(self._ray_model, self._ray_data)
        rbound = np.where(self._ray_model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE, 0.0, self._ray_model.geom_rbound)
        self._ray_top = float(np.max(self._ray_data.geom_xpos[:, 2] + rbound)) + 1.0

    def add_to(self, spec: mujoco.MjSpec) -> None:
        if self._has_plane:
            for geom in list(spec.worldbody.geoms):
                if geom.type == mujoco.mjtGeom.mjGEOM_PLANE:
                    spec.delete(geom)
        _add_geoms(spec, self._geoms)

    def height_at(self, x_m, y_m) -> np.ndarray:
        """The height of the first colliding ground geom a vertical ray meets (``mj_ray``); 0 m (the floor) where
        it meets none."""
        x, y = _xy(x_m, y_m)
        out = np.zeros(x.shape)
        flat_x, flat_y, flat_out = x.ravel(), y.ravel(), out.reshape(-1)
        point, down, geom = np.zeros(3), np.array([0.0, 0.0, -1.0]), np.zeros(1, dtype=np.int32)
        for i in range(flat_x.size):
            point[:] = (flat_x[i], flat_y[i], self._ray_top)
            distance = mujoco.mj_ray(self._ray_model, self._ray_data, point, down, None, 1, -1, geom)
            flat_out[i] = self._ray_top - distance if distance >= 0 else 0.0
        return flat_out.reshape(x.shape)

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_ray_data", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._ray_data = mujoco.MjData(self._ray_model)
        mujoco.mj_kinematics(self._ray_model, self._ray_data)


def _static_geoms(model: mujoco.MjModel, where: str, path: str) -> list[dict]:
    """The geoms of ``model`` fixed to the world (body welded to the world, not a mocap body), in world
    coordinates, as keyword arguments for :func:`_add_geoms`."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    geoms = []
    for g in range(model.ngeom):
        body = model.geom_bodyid[g]
        if model.body_weldid[body] != 0 or model.body_mocapid[body] >= 0:
            continue
        kind = mujoco.mjtGeom(model.geom_type[g])
        if kind not in _MJCF_GEOM_TYPES:
            raise TerrainError(f"{where}: {path}: geom {g} is a {kind.name}; the ground takes planes, "
                               "heightfields, meshes and primitives")
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, data.geom_xmat[g])
        material = model.geom_matid[g]
        geom = dict(type=kind, size=model.geom_size[g].copy(), pos=data.geom_xpos[g].copy(), quat=quat,
                    friction=model.geom_friction[g].copy(), condim=int(model.geom_condim[g]),
                    priority=int(model.geom_priority[g]), solref=model.geom_solref[g].copy(),
                    solimp=model.geom_solimp[g].copy(), solmix=float(model.geom_solmix[g]),
                    margin=float(model.geom_margin[g]), gap=float(model.geom_gap[g]),
                    contype=int(model.geom_contype[g]), conaffinity=int(model.geom_conaffinity[g]),
                    group=int(model.geom_group[g]),
                    rgba=(model.mat_rgba[material] if material >= 0 else model.geom_rgba[g]).copy())
        if kind == mujoco.mjtGeom.mjGEOM_HFIELD:
            h = model.geom_dataid[g]
            nrow, ncol, adr = model.hfield_nrow[h], model.hfield_ncol[h], model.hfield_adr[h]
            geom["hfield"] = (int(nrow), int(ncol), model.hfield_size[h].copy(),
                              model.hfield_data[adr:adr + nrow * ncol].copy())
        elif kind == mujoco.mjtGeom.mjGEOM_MESH:
            m = model.geom_dataid[g]
            verts = model.mesh_vert[model.mesh_vertadr[m]:model.mesh_vertadr[m] + model.mesh_vertnum[m]]
            faces = model.mesh_face[model.mesh_faceadr[m]:model.mesh_faceadr[m] + model.mesh_facenum[m]]
            rotation = data.geom_xmat[g].reshape(3, 3)
            geom["mesh"] = (verts @ rotation.T + data.geom_xpos[g], faces.copy())  # world frame
            geom["pos"], geom["quat"] = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        geoms.append(geom)
    if not any(g["contype"] or g["conaffinity"] for g in geoms):
        raise TerrainError(f"{where}: {path} has no static geom that collides (contype or conaffinity set) to "
                           "stand on")
    return geoms


def _add_geoms(spec: mujoco.MjSpec, geoms: list[dict], *, rays: bool = False) -> None:
    """Adds :func:`_static_geoms`'s geoms to ``spec``'s world, named ``terrain_mjcf_<i>`` (their heightfields and
    meshes too). With ``rays`` planes are made unbounded (MuJoCo collides with a plane everywhere but casts rays
    only onto its drawn size)."""
    for i, geom in enumerate(geoms):
        geom = dict(geom)
        name = f"{TERRAIN_PREFIX}mjcf_{i}"
        extra = {}
        hfield, mesh = geom.pop("hfield", None), geom.pop("mesh", None)
        if hfield is not None:
            nrow, ncol, size, data = hfield
            spec.add_hfield(name=name, nrow=nrow, ncol=ncol, size=size.tolist(), userdata=data.tolist())
            extra["hfieldname"] = name
        if mesh is not None:
            verts, faces = mesh
            spec.add_mesh(name=name, uservert=verts.ravel().tolist(), userface=faces.ravel().tolist())
            extra["meshname"] = name
        if rays and geom["type"] == mujoco.mjtGeom.mjGEOM_PLANE:
            geom["size"] = np.array([0.0, 0.0, geom["size"][2]])
        kwargs = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in geom.items()}
        spec.worldbody.add_geom(name=name, **kwargs, **extra)


# ---------------------------------------------------------------------------------------------------- making one
def make_terrain(terrain: "str | Terrain | Mapping | None" = None, /, **options) -> Terrain:
    """A terrain from what a caller or a config gives: ``None`` (flat), a :class:`Terrain` (as it is), a registered
    name (or an import path already imported with ``TERRAINS.import_path``) with keyword ``options``, a mapping
    ``{"name": ..., **options}``, or the path of a terrain file (``.png``: :class:`Heightmap`, ``.xml``:
    :class:`MjcfGround`).

    Raises :class:`TerrainError` (a ``ValueError``, one line) for an unknown name, an unknown option (naming the
    valid ones), a bad value, a missing or malformed file, before any simulation.

    Example:
        >>> make_terrain({"name": "stairs", "difficulty": 1.0}).key()
        {'name': 'stairs', 'difficulty': 1.0}
        >>> make_terrain("flat", slope=0.1)
        Traceback (most recent call last):
        ...
        hierloco.envs.terrain.TerrainError: terrain 'flat' has no option 'slope' (its options: difficulty, seed)
    """
    if isinstance(terrain, Terrain):
        if options:
            raise TerrainError(f"terrain {terrain.describe()!r} is already made; options {sorted(options)} cannot "
                               "be added to it")
        return terrain
    if terrain is None:
        terrain = "flat"
    if isinstance(terrain, Mapping):
        terrain = dict(terrain)
        name = terrain.pop("name", None)
        if name is None:
            raise TerrainError(f"a terrain given as a mapping needs a 'name' (terrains: {', '.join(TERRAINS.names())})")
        return make_terrain(name, **{**terrain, **options})
    if isinstance(terrain, os.PathLike):
        terrain = os.fspath(terrain)
    if not isinstance(terrain, str):
        raise TerrainError(f"terrain must be a name, a mapping with a name, a file or a Terrain, got {terrain!r}")
    suffix = os.path.splitext(terrain)[1].lower()
    if suffix in (".png", ".xml") and terrain not in TERRAINS:
        return make_terrain("heightmap" if suffix == ".png" else "mjcf", path=terrain, **options)
    try:
        cls = TERRAINS[terrain]
    except ValueError as error:
        raise TerrainError(_one_line(error)) from None
    if not (isinstance(cls, type) and issubclass(cls, Terrain)):
        raise TerrainError(f"terrain {terrain!r} is not a hierloco.envs.terrain.Terrain subclass")
    problems = TERRAINS.check_options(terrain, options)
    if problems:
        raise TerrainError(problems[0])
    return cls(**options)


def standing_qpos_on(terrain: Terrain | None, model: mujoco.MjModel, robot: RobotSpec, x: float = 0.0,
                     y: float = 0.0, yaw: float = START_YAW) -> np.ndarray:
    """The full ``qpos`` of ``robot`` standing at ``(x, y)`` facing ``yaw`` on ``terrain``: the standing pose
    (:func:`hierloco.envs.robots.standing_qpos`) lifted (or lowered) so that the robot's colliding geom closest
    to the ground is :data:`START_CLEARANCE_M` above the highest ground under it (each geom's footprint is the
    disc of its bounding radius). On flat ground (or ``None``): ``standing_qpos`` exactly."""
    qpos = standing_qpos(model, robot, x, y, yaw)
    if terrain is None or terrain.is_flat:
        return qpos
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    robot_geoms = [g for g in range(model.ngeom) if model.body_weldid[model.geom_bodyid[g]] != 0
                   and (model.geom_contype[g] or model.geom_conaffinity[g])]
    lift = max(terrain.highest_in_disc(float(data.geom_xpos[g][0]), float(data.geom_xpos[g][1]),
                                       float(model.geom_rbound[g])) - _geom_bottom(model, data, g)
               for g in robot_geoms)
    qpos[2] += lift + START_CLEARANCE_M
    return qpos


# ---------------------------------------------------------------------------------------------------- pushes
@dataclass(frozen=True)
class PushEvent:
    """One push given to one copy of the batched simulator.

    Attributes:
        copy: which copy (0 .. B - 1).
        episode_step: the control step since the copy's reset at whose start the push acted.
        run_step: the control step of the :meth:`~hierloco.envs.batched_sim.BatchedSimulator.run` call it acted in
            (``-1``: given between runs with :meth:`~hierloco.envs.batched_sim.BatchedSimulator.push`).
        time_s: the simulation time at the push, s.
        velocity_change_mps: ``(dvx, dvy)`` added to the trunk's velocity, world frame, m/s.
        direction_rad: the push's direction in the robot's local (yaw) frame (0 forward, pi / 2 to its left).
    """

    copy: int
    episode_step: int
    run_step: int
    time_s: float
    velocity_change_mps: tuple[float, float]
    direction_rad: float


class Pushes:
    """Velocity impulses on the trunk at random times: every ``interval_s`` (uniform in that range, drawn anew
    after each push, per copy, from the simulator's seed) the whole robot's horizontal velocity changes by
    ``magnitude_mps`` in ``direction_rad`` of its local frame (``None``: uniform in [0, 2 pi)), as legged_gym's
    pushes. ``magnitude_mps=0`` (the default) gives no pushes.

    Args:
        magnitude_mps: the velocity change, m/s (0 to 10).
        direction_rad: the direction relative to the robot's heading, rad (0 forward, pi / 2 to the left);
            ``None``: random.
        interval_s: ``(low, high)`` time between pushes, s (at least one 0.01 s control step; the first push comes
            one interval after a reset).

    Example:
        >>> Pushes(magnitude_mps=0.5).key()
        {'magnitude_mps': 0.5, 'direction_rad': None, 'interval_s': [2.0, 4.0]}
    """

    def __init__(self, *, magnitude_mps: float = 0.0, direction_rad: float | None = None,
                 interval_s: tuple[float, float] = (2.0, 4.0)):
        where = "pushes"
        self.magnitude_mps = _real(where, "magnitude_mps", magnitude_mps, low=0.0, high=10.0)
        self.direction_rad = None if direction_rad is None else _real(where, "direction_rad", direction_rad)
        self.interval_s = _range(where, "interval_s", interval_s, low=CONTROL_TIMESTEP, high=3600.0)

    @property
    def active(self) -> bool:
        return self.magnitude_mps > 0

    def key(self) -> dict[str, Any]:
        """``{}`` without pushes; else every option."""
        if not self.active:
            return {}
        return {"magnitude_mps": self.magnitude_mps, "direction_rad": self.direction_rad,
                "interval_s": list(self.interval_s)}

    def interval_steps(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` times to the next push, in whole control steps (at least 1)."""
        seconds = rng.uniform(self.interval_s[0], self.interval_s[1], count)
        return np.maximum(1, np.round(seconds / CONTROL_TIMESTEP)).astype(np.int64)

    def direction(self, rng: np.random.Generator) -> float:
        """The direction of the next push in the robot's frame, rad."""
        return float(rng.uniform(0.0, 2 * np.pi)) if self.direction_rad is None else self.direction_rad


def make_pushes(pushes: "Pushes | Mapping | None" = None) -> Pushes:
    """``None`` (no pushes), a :class:`Pushes`, or a mapping of its options."""
    if pushes is None:
        return Pushes()
    if isinstance(pushes, Pushes):
        return pushes
    if isinstance(pushes, Mapping):
        return _build(Pushes, "pushes", pushes)
    raise TerrainError(f"pushes must be a mapping of options or a Pushes, got {pushes!r}")


# ---------------------------------------------------------------------------------------------------- dynamics
class DynamicsRandomization:
    """Randomised dynamics: per simulated robot and episode, each drawn uniformly from its range (seeded by the
    simulator's seed) and applied to that copy's own model. The defaults change nothing (:meth:`key` is ``{}``);
    :meth:`standard` gives the ranges of ``docs/terrain.md``.

    Args:
        payload_fraction: ``(low, high)`` payload added to the base body, as a fraction of the robot's total mass
            (its inertia grows in proportion).
        com_offset_m: the base body's centre of mass moves by up to this, m, along each axis.
        friction: ``(low, high)`` sliding friction of the feet's contacts (``None``: the model's own); the feet take
            priority over the ground, but not over slippery patches.
        kp_scale: ``(low, high)`` factor on every servo's stiffness kp.
        torque_scale: ``(low, high)`` factor on every servo's torque limit.
        latency_steps: ``(low, high)`` whole 2 ms physics steps by which the servos act late (on top of the robot's
            own ``servo_latency``).
        damping_scale: ``(low, high)`` factor on every leg joint's damping.

    Example:
        >>> DynamicsRandomization(friction=(0.4, 1.0)).key()
        {'friction': [0.4, 1.0]}
    """

    def __init__(self, *, payload_fraction: tuple[float, float] = (0.0, 0.0), com_offset_m: float = 0.0,
                 friction: tuple[float, float] | None = None, kp_scale: tuple[float, float] = (1.0, 1.0),
                 torque_scale: tuple[float, float] = (1.0, 1.0), latency_steps: tuple[int, int] = (0, 0),
                 damping_scale: tuple[float, float] = (1.0, 1.0)):
        where = "randomization"
        self.payload_fraction = _range(where, "payload_fraction", payload_fraction, low=0.0, high=1.0)
        self.com_offset_m = _real(where, "com_offset_m", com_offset_m, low=0.0, high=0.2)
        self.friction = None if friction is None else _range(where, "friction", friction, low=0.01, high=5.0)
        self.kp_scale = _range(where, "kp_scale", kp_scale, low=0.05, high=10.0)
        self.torque_scale = _range(where, "torque_scale", torque_scale, low=0.05, high=10.0)
        self.latency_steps = _range(where, "latency_steps", latency_steps, low=0,
                                    high=int(round(0.5 / PHYSICS_TIMESTEP)), whole=True)
        self.damping_scale = _range(where, "damping_scale", damping_scale, low=0.0, high=10.0)

    @classmethod
    def standard(cls) -> "DynamicsRandomization":
        """The ranges of ``docs/terrain.md`` (as legged_gym's and mujoco_playground's): payload 0-10 % of the
        mass, CoM within 2 cm, foot friction 0.4-1.25, kp and torque limit 0.8-1.2 x, latency 0-10 ms, damping
        0.5-1.5 x."""
        return cls(payload_fraction=(0.0, 0.1), com_offset_m=0.02, friction=(0.4, 1.25), kp_scale=(0.8, 1.2),
                   torque_scale=(0.8, 1.2), latency_steps=(0, 5), damping_scale=(0.5, 1.5))

    def options(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in _keyword_defaults(type(self))}

    def key(self) -> dict[str, Any]:
        """The options that differ from the defaults (``{}``: nominal dynamics)."""
        defaults = _keyword_defaults(type(self))
        key = without_defaults(self.options(), defaults)
        return {name: list(value) if isinstance(value, tuple) else value for name, value in key.items()}

    @property
    def active(self) -> bool:
        return bool(self.key())

    def sample(self, rng: np.random.Generator, count: int) -> dict[str, np.ndarray]:
        """``count`` draws: ``payload_fraction`` (count), ``com_offset_m`` (count x 3), ``friction`` (count, NaN
        when not randomised), ``kp_scale``, ``torque_scale``, ``latency_steps`` (ints), ``damping_scale``."""
        def uniform(bounds):
            return rng.uniform(bounds[0], bounds[1], count)

        return {"payload_fraction": uniform(self.payload_fraction),
                "com_offset_m": rng.uniform(-self.com_offset_m, self.com_offset_m, (count, 3)),
                "friction": uniform(self.friction) if self.friction is not None else np.full(count, np.nan),
                "kp_scale": uniform(self.kp_scale), "torque_scale": uniform(self.torque_scale),
                "latency_steps": rng.integers(self.latency_steps[0], self.latency_steps[1] + 1, count),
                "damping_scale": uniform(self.damping_scale)}

    def apply(self, model: mujoco.MjModel, nominal: mujoco.MjModel, robot: RobotSpec, draw: Mapping[str, Any],
              feet: np.ndarray) -> None:
        """Sets ``model`` (a copy of ``nominal``) to ``nominal`` with one draw of :meth:`sample` (a mapping of
        scalars; ``com_offset_m`` a 3-vector); ``feet`` are the foot geoms
        (:func:`hierloco.envs.robots.spec.foot_geoms`)."""
        base = nominal.body(robot.base_body).id
        mass = float(nominal.body_mass[base])
        model.body_mass[base] = mass + float(draw["payload_fraction"]) * float(np.sum(nominal.body_mass))
        model.body_inertia[base] = nominal.body_inertia[base] * (model.body_mass[base] / mass if mass > 0 else 1.0)
        model.body_ipos[base] = nominal.body_ipos[base] + np.asarray(draw["com_offset_m"])
        model.geom_friction[:] = nominal.geom_friction
        model.geom_priority[:] = nominal.geom_priority
        if np.isfinite(draw["friction"]):
            model.geom_friction[feet, 0] = float(draw["friction"])
            model.geom_priority[feet] = np.maximum(nominal.geom_priority[feet], 1)
        model.actuator_gainprm[:, 0] = nominal.actuator_gainprm[:, 0] * float(draw["kp_scale"])
        model.actuator_biasprm[:, 1] = nominal.actuator_biasprm[:, 1] * float(draw["kp_scale"])
        model.actuator_forcerange[:] = nominal.actuator_forcerange * float(draw["torque_scale"])
        dofs = [nominal.jnt_dofadr[nominal.joint(name).id] for name in robot.joint_names]
        model.dof_damping[dofs] = nominal.dof_damping[dofs] * float(draw["damping_scale"])
        mujoco.mj_setConst(model, mujoco.MjData(model))


def make_randomization(randomization: "DynamicsRandomization | Mapping | str | None" = None
                       ) -> DynamicsRandomization:
    """``None`` (nominal), a :class:`DynamicsRandomization`, ``"standard"`` (:meth:`DynamicsRandomization.standard`)
    or a mapping of its options."""
    if randomization is None:
        return DynamicsRandomization()
    if isinstance(randomization, DynamicsRandomization):
        return randomization
    if randomization == "standard":
        return DynamicsRandomization.standard()
    if isinstance(randomization, Mapping):
        return _build(DynamicsRandomization, "randomization", randomization)
    raise TerrainError(f"randomization must be 'standard', a mapping of options or a DynamicsRandomization, got "
                       f"{randomization!r}")


def _build(cls, what: str, options: Mapping):
    valid = _keyword_defaults(cls)
    unknown = [key for key in options if key not in valid]
    if unknown:
        raise TerrainError(f"{what} has no option {unknown[0]!r} (its options: {', '.join(valid)})")
    return cls(**options)


def random_stream(seed: int | None, stream: int) -> np.random.Generator:
    """An independent generator for one kind of draw (pushes 1, dynamics 2) from a simulator's ``seed``, leaving
    the simulator's own generator (reset noise) as it was."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream,)))


__all__ = ["TERRAINS", "Blocks", "DynamicsRandomization", "Flat", "Heightmap", "HeightfieldTerrain", "MjcfGround",
           "PushEvent", "Pushes", "Rough", "Slippery", "Slope", "Stairs", "Terrain", "TerrainError", "BoxTerrain",
           "make_pushes", "make_randomization", "make_terrain", "random_stream", "standing_qpos_on"]

"""Navigation: a cluttered arena of boxes, a collision-free path from a grid planner, and clearance checks
(``docs/index.md``, Navigation; the paper's Fig. 2 uses LAT with a waypoint planner this way).

The path is planned with A* on an occupancy grid whose obstacles are inflated by the robot's footprint radius,
shortened by line-of-sight shortcuts and resampled evenly. The task :class:`Navigation` (registered as
``navigation``) is trajectory tracking along that path in the arena: its boxes are in the robots' world during an
evaluation (:attr:`hierloco.envs.tasks.Task.obstacles`), so a recipe evaluates it like any task
(``+eval.tasks.navigation_arena1={task: navigation, arena_seed: 1, inflation: 0.65}``), on any terrain too
(``terrain: {name: rough, difficulty: 0.3}`` beside its options, or ``eval.terrain``): the boxes then reach from the
floor to their own height above the highest ground under them
(:meth:`hierloco.envs.terrain.Terrain.place_obstacles`) and the path is planned on the arena's floor plan as on flat
ground (``docs/terrain.md``).

Example:
    >>> arena = cluttered_arena(seed=0)
    >>> path = plan_path(arena, inflation=0.35)  # P x 2 world-frame points, m
    >>> bool(clearance(arena, path).min() >= 0.35 - 0.05)  # at least the inflation, to the grid resolution
    True
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from hierloco.envs.robots import Obstacle
from hierloco.envs.tasks import TASKS, TrajectoryTracking, _number, _points, _whole


@dataclass(frozen=True)
class Arena:
    """Static box obstacles, a start and a goal (m, world frame), inside ``bounds`` ``(xmin, xmax, ymin, ymax)``."""

    obstacles: tuple[Obstacle, ...]
    start: tuple[float, float]
    goal: tuple[float, float]
    bounds: tuple[float, float, float, float]


def cluttered_arena(seed: int = 0, num_obstacles: int = 10, goal: tuple[float, float] = (3.0, 4.0),
                    margin: float = 1.0, keep_clear: float = 0.7, max_half_size: float = 0.4) -> Arena:
    """Random boxes scattered about the straight line from the start (the origin) to ``goal`` (so that the path
    has to weave between them), none within ``keep_clear`` m of either end."""
    if num_obstacles < 0 or not keep_clear > 0:
        raise ValueError("need num_obstacles >= 0 and keep_clear > 0")
    rng = np.random.default_rng(seed)
    start = (0.0, 0.0)
    bounds = (min(start[0], goal[0]) - margin, max(start[0], goal[0]) + margin,
              min(start[1], goal[1]) - margin, max(start[1], goal[1]) + margin)
    obstacles: list[Obstacle] = []
    attempts = 0
    while len(obstacles) < num_obstacles and attempts < 1000 * max(1, num_obstacles):
        attempts += 1
        half = (float(rng.uniform(0.1, max_half_size)), float(rng.uniform(0.1, max_half_size)), 0.25)
        along, across = rng.uniform(0.1, 0.9), rng.uniform(-1.2, 1.2)
        direction = np.subtract(goal, start) / max(1e-9, float(np.linalg.norm(np.subtract(goal, start))))
        x, y = np.add(start, along * np.subtract(goal, start)) + across * np.array([-direction[1], direction[0]])
        candidate = Obstacle(float(x), float(y), half, float(rng.uniform(-math.pi, math.pi)))
        points = np.array([start, goal], dtype=float)
        if np.all(_box_distance(candidate, points) > keep_clear):
            obstacles.append(candidate)
    return Arena(tuple(obstacles), start, (float(goal[0]), float(goal[1])), bounds)


def _box_distance(obstacle: Obstacle, points: np.ndarray) -> np.ndarray:
    """Signed distance (m) from ``... x 2`` points to the box footprint (negative inside)."""
    c, s = math.cos(obstacle.yaw), math.sin(obstacle.yaw)
    d = points - np.array([obstacle.x, obstacle.y])
    local = np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1)
    q = np.abs(local) - np.array(obstacle.half_size[:2])
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(np.max(q, axis=-1), 0.0)
    return outside + inside


def clearance(arena: Arena, points: np.ndarray) -> np.ndarray:
    """Distance (m) from ``... x 2`` points to the nearest obstacle footprint (negative inside one; inf if none)."""
    points = np.asarray(points, dtype=float)
    if not arena.obstacles:
        return np.full(points.shape[:-1], np.inf)
    return np.min([_box_distance(o, points) for o in arena.obstacles], axis=0)


FOOTPRINT_MARGIN = 0.1  # m kept beyond the robot's footprint radius by the default inflation


def footprint_radius(robot) -> float:
    """The robot's footprint radius in m: the largest horizontal distance from its base to a foot in the standing
    pose (A1 about 0.24 m, Daisy about 0.55 m). A path inflated by this plus :data:`FOOTPRINT_MARGIN` keeps the feet,
    not only the CoM, clear of the obstacles.

    Example:
        >>> round(footprint_radius("daisy"), 2) > round(footprint_radius("a1"), 2)
        True
    """
    import mujoco

    from hierloco.envs.robots import compile_model, get_robot
    from hierloco.envs.robots.spec import standing_qpos

    robot = get_robot(robot)
    model = compile_model(robot)
    data = mujoco.MjData(model)
    data.qpos[:] = standing_qpos(model, robot, yaw=0.0)
    mujoco.mj_kinematics(model, data)
    feet = np.array([data.site_xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, leg.foot_site)]
                     for leg in robot.legs])
    return float(np.max(np.linalg.norm(feet[:, :2] - data.qpos[:2], axis=1)))


def plan_path(arena: Arena, *, inflation: float = 0.35, resolution: float = 0.05, spacing: float = 0.05
              ) -> np.ndarray:
    """A collision-free path from start to goal (``P x 2``, m) keeping ``inflation`` m from every obstacle.

    A* over an 8-connected occupancy grid of ``resolution`` m, then line-of-sight shortcuts, then points every
    ``spacing`` m. Raises ``ValueError`` when no path exists.
    """
    xmin, xmax, ymin, ymax = arena.bounds
    xs = np.arange(xmin, xmax + 1e-9, resolution)
    ys = np.arange(ymin, ymax + 1e-9, resolution)
    grid_points = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1)
    free = clearance(arena, grid_points) > inflation

    def cell(point):
        return (int(round((point[0] - xmin) / resolution)), int(round((point[1] - ymin) / resolution)))

    start, goal = cell(arena.start), cell(arena.goal)
    for name, c in (("start", start), ("goal", goal)):
        if not (0 <= c[0] < free.shape[0] and 0 <= c[1] < free.shape[1]) or not free[c]:
            raise ValueError(f"the {name} is inside an (inflated) obstacle or outside the arena")
    cells = _astar(free, start, goal)
    waypoints = [cells[0]]
    i = 0
    while i < len(cells) - 1:  # shortcut: jump to the farthest cell in line of sight
        j = len(cells) - 1
        while j > i + 1 and not _line_free(free, cells[i], cells[j]):
            j -= 1
        waypoints.append(cells[j])
        i = j
    corners = np.array([[xmin + a * resolution, ymin + b * resolution] for a, b in waypoints])
    corners[0], corners[-1] = arena.start, arena.goal
    segments = [np.linspace(p, q, max(2, int(np.ceil(np.linalg.norm(q - p) / spacing)) + 1))[:-1]
                for p, q in zip(corners[:-1], corners[1:])]
    return np.concatenate(segments + [corners[-1:]])


def _astar(free: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]]:
    moves = [(dx, dy, math.hypot(dx, dy)) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]

    def heuristic(c):
        dx, dy = abs(c[0] - goal[0]), abs(c[1] - goal[1])
        return max(dx, dy) + (math.sqrt(2) - 1) * min(dx, dy)

    frontier = [(heuristic(start), 0.0, start)]
    cost, parent = {start: 0.0}, {start: None}
    while frontier:
        _, g, current = heapq.heappop(frontier)
        if current == goal:
            path = [current]
            while parent[path[-1]] is not None:
                path.append(parent[path[-1]])
            return path[::-1]
        if g > cost[current]:
            continue
        for dx, dy, step in moves:
            nxt = (current[0] + dx, current[1] + dy)
            if not (0 <= nxt[0] < free.shape[0] and 0 <= nxt[1] < free.shape[1]) or not free[nxt]:
                continue
            new_cost = g + step
            if new_cost < cost.get(nxt, math.inf):
                cost[nxt], parent[nxt] = new_cost, current
                heapq.heappush(frontier, (new_cost + heuristic(nxt), new_cost, nxt))
    raise ValueError("no collision-free path from start to goal in this arena")


def _line_free(free: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    steps = int(max(abs(b[0] - a[0]), abs(b[1] - a[1]))) * 2 + 1
    line = np.rint(np.linspace(a, b, steps)).astype(int)
    return bool(np.all(free[line[:, 0], line[:, 1]]))


@TASKS.register("navigation")
class Navigation(TrajectoryTracking):
    """Follow the collision-free path through a cluttered arena to its goal (one episode per task).

    The arena is :func:`cluttered_arena` of ``arena_seed``, ``num_obstacles`` and ``goal`` (m; the robot starts at
    the origin facing +y); the path is :func:`plan_path` keeping ``inflation`` m from every box (a robot's
    :func:`footprint_radius` plus :data:`FOOTPRINT_MARGIN`: A1 0.34 m, Daisy 0.65 m); the reference point moves
    along it at ``speed`` m/s for the path's length plus ``extra_steps`` task steps, as in
    :class:`~hierloco.envs.tasks.TrajectoryTracking`. ``final_error`` is the distance to the goal (success within
    0.2 m); per episode it reports ``path_distance`` (mean CoM distance to the path, m) and ``clearance`` (the
    closest the CoM came to a box, m). An arena with no path raises ``ValueError`` when the task is made.

    Example:
        >>> task = Navigation(arena_seed=0, num_obstacles=10, inflation=0.35)
        >>> len(task.obstacles), task.num_episodes, bool(task.length >= 5.0)  # at least the 5 m straight line
        (10, 1, True)
        >>> bool(clearance(task.arena, task.path.numpy()).min() >= 0.35 - 0.05)
        True
    """

    kind = "navigation"
    figures = ("arena",)

    def __init__(self, arena_seed: int = 0, num_obstacles: int = 10, goal: tuple[float, float] = (3.0, 4.0),
                 inflation: float = 0.35, speed: float = 0.1, extra_steps: int = 10, name: str | None = None):
        goal = _points("goal", [goal], "an (x, y) point in m")[0]
        self.inflation = _number("inflation", inflation)
        if self.inflation < 0:
            raise ValueError(f"inflation must be >= 0 m, got {inflation!r}")
        self.arena = cluttered_arena(seed=_whole("arena_seed", arena_seed, 0),
                                     num_obstacles=_whole("num_obstacles", num_obstacles, 0),
                                     goal=(float(goal[0]), float(goal[1])))
        super().__init__(path=plan_path(self.arena, inflation=self.inflation), speed=speed,
                         extra_steps=extra_steps, name=name)
        self.obstacles = self.arena.obstacles

    def extra_metrics(self, com_paths, episodes=None) -> dict[str, np.ndarray]:
        """``path_distance`` (m, mean over the CoM path) and ``clearance`` (m, the CoM's closest approach to a box;
        negative inside one), per episode of ``E x S x >=2`` CoM paths."""
        positions = np.asarray(com_paths)[..., :2]
        return {**super().extra_metrics(com_paths, episodes), "clearance": clearance(self.arena, positions).min(1)}

    def training_split(self) -> TrajectoryTracking:
        """The first half of the path, in the same arena."""
        split = super().training_split()
        split.obstacles = self.obstacles
        return split

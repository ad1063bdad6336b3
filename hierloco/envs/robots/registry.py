"""Finding a robot by name or path: the built-in robots, robots registered in this process, YAML files and robots
that installed packages add through the ``hierloco.robots`` entry-point group.

:func:`get_robot` resolves, in this order: a :class:`RobotSpec` (returned as is); a registered name; a path to a
YAML description (any string ending in .yaml / .yml, or an existing file; loaded once per file version); the name
of an entry point in the ``hierloco.robots`` group (loaded on first lookup, then registered). The string that
finds a robot again in another process (a Ray worker, a subprocess) is its :attr:`RobotSpec.reference`; see
:func:`robot_reference`.

An installed package adds robots in its ``pyproject.toml``; an entry point names a :class:`RobotSpec` or a
zero-argument callable returning one, and its name must be the robot's name:

.. code-block:: toml

    [project.entry-points."hierloco.robots"]
    myquad = "my_package.robots:MYQUAD"
    myhex = "my_package.robots:make_myhex"

Example:
    >>> get_robot("a1").name, get_robot("a1").source
    ('a1', 'builtin')
    >>> "daisy" in available_robots()
    True
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import os
from pathlib import Path

from hierloco.envs.robots.spec import ENTRY_POINT_SOURCE_PREFIX, RobotSpec
from hierloco.envs.robots.yaml_robot import is_robot_file, load_robot_yaml, read_robot_yaml

ENTRY_POINT_GROUP = "hierloco.robots"

ROBOTS: dict[str, RobotSpec] = {}
_YAML_CACHE: dict[str, tuple[tuple, RobotSpec]] = {}  # absolute path -> (file versions, robot)


def register_robot(robot: RobotSpec) -> RobotSpec:
    """Make ``robot`` available by its name to :func:`get_robot` (and so to every recipe) in this process."""
    if not isinstance(robot, RobotSpec):
        raise ValueError(f"register_robot takes a RobotSpec, got {type(robot).__name__}")
    ROBOTS[robot.name] = robot
    return robot


def get_robot(robot: str | os.PathLike | RobotSpec) -> RobotSpec:
    """The robot description for a registered name, a YAML file or an entry point (see the module docstring), or
    ``robot`` itself if it is already a description."""
    if isinstance(robot, RobotSpec):
        return robot
    if isinstance(robot, os.PathLike):
        robot = os.fspath(robot)
    if not isinstance(robot, str):
        raise ValueError(f"robot must be a name, a path to a robot .yaml file or a RobotSpec, got {robot!r}")
    if robot in ROBOTS:
        return ROBOTS[robot]
    if is_robot_file(robot):
        return _load_yaml_cached(robot)
    loaded = _load_entry_point(robot)
    if loaded is not None:
        return loaded
    raise ValueError(f"unknown robot {robot!r}; robots: {available_robots()} (or give the path of a robot .yaml "
                     "file)")


def available_robots() -> list[str]:
    """Names :func:`get_robot` knows: registered robots and the entry points of installed packages."""
    return sorted(set(ROBOTS) | {ep.name for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)})


def robot_reference(robot: str | os.PathLike | RobotSpec) -> str:
    """The string that finds ``robot`` again with :func:`get_robot` in any process (e.g. to hand to a worker): the
    absolute path of a YAML robot, else the name. Raises :class:`ValueError` for a robot that cannot be found.

    Example:
        >>> robot_reference("a1")
        'a1'
    """
    return get_robot(robot).reference


def _file_version(path: Path) -> tuple:
    stat = path.stat()
    return str(path), stat.st_mtime_ns, stat.st_size


def _load_yaml_cached(path: str) -> RobotSpec:
    """Loads a YAML robot once per version of the YAML and MJCF files (one instance, one cached fingerprint)."""
    key = str(Path(path).absolute())
    cached = _YAML_CACHE.get(key)
    if cached is not None:
        versions, robot = cached
        try:
            if tuple(_file_version(Path(version[0])) for version in versions) == versions:
                return robot
        except OSError:  # a file went away: load again, which reports it
            pass
    _, mjcf = read_robot_yaml(key)
    versions = (_file_version(Path(key)), _file_version(mjcf))
    robot = load_robot_yaml(key)
    _YAML_CACHE[key] = (versions, robot)
    return robot


def _load_entry_point(name: str) -> RobotSpec | None:
    found = [ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
    if not found:
        return None
    if len({ep.value for ep in found}) > 1:
        raise ValueError(f"robot {name!r} is provided by several {ENTRY_POINT_GROUP!r} entry points: "
                         f"{sorted({ep.value for ep in found})}")
    entry = found[0]
    where = f"robot {name!r} (entry point {entry.value!r} of group {ENTRY_POINT_GROUP!r})"
    try:
        target = entry.load()
        robot = target if isinstance(target, RobotSpec) else target() if callable(target) else target
    except Exception as error:  # a user's package: report whatever it raised, naming the entry point
        raise ValueError(f"{where}: loading it failed: {type(error).__name__}: {error}") from error
    if not isinstance(robot, RobotSpec):
        raise ValueError(f"{where}: must name a RobotSpec or a zero-argument callable returning one, got "
                         f"{type(robot).__name__}")
    if robot.name != name:
        raise ValueError(f"{where}: the entry point's name must be the robot's name, got a robot named {robot.name!r}")
    return register_robot(dataclasses.replace(robot, source=f"{ENTRY_POINT_SOURCE_PREFIX}{name} = {entry.value}"))


__all__ = ["ENTRY_POINT_GROUP", "ROBOTS", "available_robots", "get_robot", "register_robot", "robot_reference"]

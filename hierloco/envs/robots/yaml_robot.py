"""Robots described by a YAML file: the MJCF file and the keyword arguments of :func:`robot_from_mjcf`.

The YAML keys are ``mjcf`` (the MJCF file, relative to the YAML file's directory or absolute) and the keyword
arguments of :func:`hierloco.envs.robots.robot_from_mjcf`. Every error names the file and the key. A YAML
robot is found again from its path alone, in any process (``get_robot("path/to/robot.yaml")``), so a worker that
receives only the config string builds the same robot.

Example (``docs/robots.md`` has a complete file):

.. code-block:: yaml

    mjcf: quadruped20.xml
    name: quadruped20
    base_body: trunk
    legs: {FR: [FR_hip_joint, FR_thigh_joint, FR_calf_joint], ...}
    feet: {FR: FR_foot, ...}
    standing_pose: [0.0, 0.8, -1.6]      # one leg's angles, for every leg
    gait_groups: [[FR, RL], [FL, RR]]
    kp: 150

    >>> from hierloco.envs.robots import load_robot_yaml
    >>> robot = load_robot_yaml("tests/fixtures/quadruped20/quadruped20.yaml")  # doctest: +SKIP
    >>> robot.source  # doctest: +SKIP
    'yaml:/.../tests/fixtures/quadruped20/quadruped20.yaml'
"""

from __future__ import annotations

import difflib
import inspect
import os
from pathlib import Path
from typing import Any, Callable

from hierloco.envs.robots.mjcf import robot_from_mjcf
from hierloco.envs.robots.spec import YAML_SOURCE_PREFIX, RobotSpec, is_number
from hierloco.io import ArtifactError, brief, load_yaml

YAML_SUFFIXES = (".yaml", ".yml")
MJCF_KEY = "mjcf"


def _text(value) -> bool:
    return isinstance(value, str) and bool(value)


def _texts(value) -> bool:
    return isinstance(value, list) and bool(value) and all(_text(v) for v in value)


def _number(value) -> bool:
    return is_number(value)  # the value itself (finite, positive, ...) is checked by RobotSpec, naming the joint


def _numbers(value) -> bool:
    return isinstance(value, list) and bool(value) and all(_number(v) for v in value)


def _mapping(check: Callable[[Any], bool]) -> Callable[[Any], bool]:
    return lambda value: isinstance(value, dict) and bool(value) and all(
        _text(k) and check(v) for k, v in value.items())


_PER_JOINT = "a number, a list of numbers (one per joint, or one leg's) or a mapping leg name -> list of numbers"
# key -> (check, what it must be); the keys are robot_from_mjcf's keyword arguments (checked below) and mjcf
KEY_TYPES: dict[str, tuple[Callable[[Any], bool], str]] = {
    MJCF_KEY: (_text, "the MJCF file's path (relative to this file, or absolute)"),
    "name": (_text, "a non-empty string"),
    "base_body": (_text, "a body name"),
    "legs": (_mapping(_texts), "a mapping leg name -> list of joint names"),
    "feet": (_mapping(_text), "a mapping leg name -> site or body name"),
    "standing_pose": (lambda v: _numbers(v) or _mapping(_numbers)(v),
                      "a list of angles in rad (one per joint, or one leg's) or a mapping leg name -> angles"),
    "gait_groups": (lambda v: isinstance(v, list) and len(v) > 0 and all(_texts(g) for g in v),
                    "a list of lists of leg names"),
    "standing_height": (_number, "a number in m"),
    "gait_period": (_number, "a number in s"),
    "min_height": (_number, "a number in m"),
    "command_low": (lambda v: _numbers(v) and len(v) == 3, "3 numbers: vx m/s, vy m/s, yaw_rate rad/s"),
    "command_high": (lambda v: _numbers(v) and len(v) == 3, "3 numbers: vx m/s, vy m/s, yaw_rate rad/s"),
    "rear_legs": (_texts, "a list of leg names"),
    "swing_height": (_number, "a number in m"),
    "max_roll": (_number, "a number in rad"),
    "max_pitch": (_number, "a number in rad"),
    "kp": (lambda v: _number(v) or _numbers(v) or _mapping(_numbers)(v), _PER_JOINT + " (N m / rad)"),
    "torque_limit": (lambda v: _number(v) or _numbers(v) or _mapping(_numbers)(v), _PER_JOINT + " (N m)"),
    "joint_damping": (lambda v: _number(v) or _numbers(v) or _mapping(_numbers)(v), _PER_JOINT + " (N m s / rad)"),
    "description": (_text, "a string"),
}
_PARAMETERS = inspect.signature(robot_from_mjcf).parameters
REQUIRED_KEYS = (MJCF_KEY,) + tuple(name for name, p in _PARAMETERS.items()
                                    if p.kind is p.KEYWORD_ONLY and p.default is inspect.Parameter.empty)


def is_robot_file(reference: str | os.PathLike) -> bool:
    """Whether ``reference`` names a robot description file: it ends in .yaml / .yml, or is an existing file."""
    text = os.fspath(reference)
    return text.endswith(YAML_SUFFIXES) or os.path.isfile(text)


def read_robot_yaml(path: str | os.PathLike) -> tuple[dict[str, Any], Path]:
    """The checked keyword arguments for :func:`robot_from_mjcf` in the YAML file ``path``, and the MJCF file's
    absolute path. Raises :class:`ValueError` naming the file and the key. The file is read safely
    (:func:`hierloco.io.load_yaml`: no Python objects, aliases that expand to at most 100 000 values), and a message
    shows only the start of a value (:func:`hierloco.io.brief`)."""
    path = Path(path).absolute()
    if not path.is_file():
        raise ValueError(f"robot description {str(path)!r}: no such file")
    try:
        content = load_yaml(path)
    except ArtifactError as error:
        raise ValueError(f"robot description {error}") from None
    if not isinstance(content, dict):
        raise ValueError(f"{path}: a robot description is a mapping of keys ({', '.join(REQUIRED_KEYS)}, ...), "
                         f"got {type(content).__name__}")
    for key in content:
        if key not in KEY_TYPES:
            close = difflib.get_close_matches(str(key)[:200], KEY_TYPES, n=2)
            hint = f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""
            raise ValueError(f"{path}: unknown key {brief(key)}{hint}; the keys are {', '.join(KEY_TYPES)}")
    for key in REQUIRED_KEYS:
        if key not in content:
            raise ValueError(f"{path}: missing key {key!r} (required: {', '.join(REQUIRED_KEYS)})")
    for key, value in content.items():
        check, what = KEY_TYPES[key]
        if not check(value):
            raise ValueError(f"{path}: key {key!r} must be {what}, got {brief(value)}")
    mjcf = Path(content.pop(MJCF_KEY))
    mjcf = mjcf if mjcf.is_absolute() else path.parent / mjcf
    if not mjcf.is_file():
        raise ValueError(f"{path}: key {MJCF_KEY!r}: no such MJCF file {str(mjcf)!r} (a relative path is relative "
                         "to the YAML file's directory)")
    return content, mjcf.resolve()


def load_robot_yaml(path: str | os.PathLike) -> RobotSpec:
    """The robot described by the YAML file ``path`` (see the module docstring), with
    ``source = "yaml:<absolute path>"``.

    Raises:
        ValueError: naming the file and the key: an unknown or missing key, a value of the wrong type, an MJCF
            file that does not exist, a name the MJCF does not have (with the close names it has), a bad number.
    """
    path = Path(path).absolute()
    kwargs, mjcf = read_robot_yaml(path)
    kwargs.setdefault("description", f"{kwargs['name']} ({path.name})")
    try:
        return robot_from_mjcf(mjcf, source=f"{YAML_SOURCE_PREFIX}{path}", **kwargs)
    except (ValueError, OSError) as error:
        raise ValueError(f"{path}: {error}") from error


__all__ = ["KEY_TYPES", "REQUIRED_KEYS", "YAML_SUFFIXES", "is_robot_file", "load_robot_yaml", "read_robot_yaml"]

"""Actuator and contact profiles: the same robot with other servos and foot friction, for every stage of a run.

- ``own``: the robot as described (A1: 100 N m/rad servos limited to 33.5 N m, feet of friction 0.8 on a floor of
  1.0, so contacts of 1.0; Daisy: its own gains and HEBI torque limits).
- ``stiff``: servos stiffer and stronger than the robot's own and more slippery contacts: servo gains and torque
  limits three times the robot's, and a contact friction of 0.4 (the paper's robots are simulated in PyBullet,
  Li et al., Sec. IV-A, whose servo and contact settings it does not give).
- ``stiff_servos``: the servos of ``stiff`` with the robot's own contacts, to tell the two changes apart.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> stiff = with_profile(get_robot("a1"), "stiff")
    >>> stiff.kp[0], stiff.torque_limit[0], stiff.foot_friction
    (300.0, 100.5, 0.4)
"""

from __future__ import annotations

from hierloco.envs.robots.spec import RobotSpec

STIFF_SCALE = 3.0
STIFF_FRICTION = 0.4


def _stiff_servos(robot: RobotSpec) -> RobotSpec:
    if robot.kp is None or robot.torque_limit is None:
        raise ValueError(f"robot {robot.name!r}: the stiff profiles scale kp and torque_limit, which the description "
                         "does not give")
    return robot.replace(kp=tuple(STIFF_SCALE * k for k in robot.kp),
                         torque_limit=tuple(STIFF_SCALE * t for t in robot.torque_limit))


def _stiff(robot: RobotSpec) -> RobotSpec:
    return _stiff_servos(robot).replace(foot_friction=STIFF_FRICTION)


PROFILES = {"own": lambda robot: robot, "stiff": _stiff, "stiff_servos": _stiff_servos}


def with_profile(robot: RobotSpec, profile: str = "own") -> RobotSpec:
    """``robot`` with the actuator and contact profile ``profile`` (see the module docstring)."""
    if profile not in PROFILES:
        raise ValueError(f"unknown robot profile {profile!r} (profiles: {', '.join(PROFILES)})")
    return PROFILES[profile](robot)

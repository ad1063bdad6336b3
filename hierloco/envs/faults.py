"""Fault models: the settings a robot is evaluated in, each as legs locked and legs limp.

- ``normal``: nothing broken.
- ``legs_disabled``: the paper's adverse setting (Li et al., Sec. IV-C): the two rear legs locked at their standing
  angles (MuJoCo joint equalities), their targets ignored.
- ``rear_limp``: the two rear legs unpowered: their servos exert no torque, the joints swing with their damping.
- ``one_leg_locked``: only the first rear leg locked.

In every fault the low level is the one learned in the normal setting; only the CoM dynamics are re-learned.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> fault_legs(get_robot("a1"), "one_leg_locked")
    (('RR',), ())
"""

from __future__ import annotations

FAULTS = ("normal", "legs_disabled", "rear_limp", "one_leg_locked")


def fault_legs(robot, setting: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(locked legs, limp legs)`` of ``robot`` in ``setting`` (one of :data:`FAULTS`)."""
    rear = tuple(robot.rear_legs)
    legs = {"normal": ((), ()), "legs_disabled": (rear, ()), "rear_limp": ((), rear),
            "one_leg_locked": (rear[:1], ())}
    if setting not in legs:
        raise ValueError(f"unknown setting {setting!r} (settings: {', '.join(FAULTS)})")
    return legs[setting]

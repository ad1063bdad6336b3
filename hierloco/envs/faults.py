"""Settings a robot is evaluated in: fault models (legs locked, legs limp) and a perturbed "hardware" robot.

- ``normal``: nothing broken.
- ``legs_disabled``: the paper's adverse setting (Li et al., Sec. IV-C): the two rear legs locked at their standing
  angles (MuJoCo joint equalities), their targets ignored.
- ``rear_limp``: the two rear legs unpowered: their servos exert no torque, the joints swing with their damping.
- ``one_leg_locked``: only the first rear leg locked.
- ``hardware``: nothing broken, but the robot simulated is a perturbed copy (heavier, weaker motors, less friction,
  servo latency, a noisy state estimate: :func:`hierloco.envs.robots.hardware.perturbed`), the paper's transfer
  to hardware (Li et al., Sec. IV-D).

In every setting the low level is the one learned in the normal setting; only the CoM dynamics are re-learned.
``<setting>_unadapted`` (e.g. ``hardware_unadapted``) is the same robot planned with the normal setting's CoM
model, not re-learned: what re-learning buys.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> fault_legs(get_robot("a1"), "one_leg_locked")
    (('RR',), ())
    >>> setting_robot(get_robot("a1"), "hardware_unadapted").name, is_unadapted("hardware_unadapted")
    ('a1_hardware', True)
"""

from __future__ import annotations

FAULTS = ("normal", "legs_disabled", "rear_limp", "one_leg_locked")
UNADAPTED = "_unadapted"
SETTINGS = (*FAULTS, "hardware", *(f"{s}{UNADAPTED}" for s in (*FAULTS[1:], "hardware")))


def check_setting(setting: str) -> None:
    """Raises ``ValueError`` naming ``setting`` unless it is one of :data:`SETTINGS`."""
    if setting not in SETTINGS:
        raise ValueError(f"unknown setting {setting!r} (settings: {', '.join(SETTINGS)})")


def is_unadapted(setting: str) -> bool:
    """Whether ``setting`` plans with the normal setting's CoM model (``<setting>_unadapted``)."""
    check_setting(setting)
    return setting.endswith(UNADAPTED)


def physical_setting(setting: str) -> str:
    """The robot and faults ``setting`` simulates: ``hardware_unadapted`` -> ``hardware``."""
    check_setting(setting)
    return setting.removesuffix(UNADAPTED)


def fault_legs(robot, setting: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(locked legs, limp legs)`` of ``robot`` in ``setting`` (one of :data:`SETTINGS`)."""
    rear = tuple(robot.rear_legs)
    legs = {"normal": ((), ()), "legs_disabled": (rear, ()), "rear_limp": ((), rear),
            "one_leg_locked": (rear[:1], ()), "hardware": ((), ())}
    return legs[physical_setting(setting)]


def setting_robot(robot, setting: str, hardware: dict | None = None):
    """The robot simulated in ``setting``: ``robot`` itself, or in ``hardware`` (and ``hardware_unadapted``) its
    perturbed copy with the options ``hardware`` (:data:`hierloco.envs.robots.hardware.HARDWARE` by default)."""
    if physical_setting(setting) != "hardware":
        return robot
    from hierloco.envs.robots.hardware import perturbed

    return perturbed(robot, **(hardware or {}))

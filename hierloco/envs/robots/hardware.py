"""A perturbed "hardware" copy of a robot: the simulated robot with the gap a real one shows (Li et al., Sec. IV-D:
the low level and latent space are kept from simulation; the CoM dynamics are learned again on the robot, from 2000
samples, under "tracking errors by the Realsense camera, slipping on gravel, joint tracking" and motor bandwidth).

The default perturbation, :data:`HARDWARE`, is a gap a reviewer would call realistic for a small legged robot:

- ``mass_scale`` 1.1: every body 10 % heavier than modelled (cables, electronics, a camera and battery on the base);
- ``foot_friction`` 0.5: feet on gravel and worn rubber (the simulated A1's contacts have 1.0);
- ``motor_strength`` 0.8: servo gains and torque limits at 80 % of the datasheet's (voltage sag, heating, gearbox
  losses), so joints track their targets worse;
- ``servo_latency`` 0.02 s: 20 ms from a joint target to the servo acting on it (bus and controller delays);
- ``com_noise`` (0.02 m, 0.03 rad, 0.05 m/s): the state estimator's noise on the CoM position, yaw and velocity
  (a tracking camera's drift and jitter).

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> robot = perturbed(get_robot("a1"))
    >>> robot.mass_scale, robot.kp[0], robot.foot_friction, robot.servo_latency
    (1.1, 80.0, 0.5, 0.02)
    >>> perturbed(get_robot("a1"), servo_latency=0.0).servo_latency
    0.0
"""

from __future__ import annotations

from hierloco.envs.robots.spec import RobotSpec

HARDWARE = {"mass_scale": 1.1, "foot_friction": 0.5, "motor_strength": 0.8, "servo_latency": 0.02,
            "com_noise": (0.02, 0.03, 0.05)}


def hardware_options(**changes) -> dict:
    """:data:`HARDWARE` with ``changes``; raises ``ValueError`` naming an unknown option."""
    unknown = sorted(set(changes) - set(HARDWARE))
    if unknown:
        raise ValueError(f"unknown hardware option(s) {unknown} (options: {', '.join(HARDWARE)})")
    options = {**HARDWARE, **changes}
    options["com_noise"] = tuple(float(v) for v in options["com_noise"])
    return options


def perturbed(robot: RobotSpec, **changes) -> RobotSpec:
    """``robot`` with the perturbation :data:`HARDWARE` (any option replaced by ``changes``), named
    ``<name>_hardware``. ``motor_strength`` scales ``kp`` and ``torque_limit``, which the robot must give."""
    options = hardware_options(**changes)
    strength = float(options["motor_strength"])
    if not strength > 0:
        raise ValueError(f"motor_strength must be a positive number, got {strength!r}")
    if robot.kp is None or robot.torque_limit is None:
        raise ValueError(f"robot {robot.name!r}: the hardware perturbation scales kp and torque_limit, which the "
                         "description does not give")
    return robot.replace(name=f"{robot.name}_hardware", mass_scale=float(options["mass_scale"]),
                         foot_friction=float(options["foot_friction"]),
                         kp=tuple(strength * k for k in robot.kp),
                         torque_limit=tuple(strength * t for t in robot.torque_limit),
                         servo_latency=float(options["servo_latency"]), com_noise=options["com_noise"])

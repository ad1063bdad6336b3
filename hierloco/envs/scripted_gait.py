"""A scripted gait: open-loop sinusoidal joint targets that make any robot step, for tests and benchmarks.

Example:
    >>> from hierloco.envs.robots import get_robot
    >>> sinusoidal_gait(get_robot("a1"), num_robots=2, num_steps=100).shape  # B x T x J, rad
    (2, 100, 12)
"""

from __future__ import annotations

import numpy as np

from hierloco.envs.robots import CONTROL_TIMESTEP, RobotSpec


def sinusoidal_gait(robot: RobotSpec, num_robots: int, num_steps: int, amplitude: float = 0.15,
                    frequency: float = 2.0, seed: int = 0, min_scale: float = 0.7) -> np.ndarray:
    """``B x T x J`` joint targets (rad): the standing pose plus one sinusoid per joint at ``frequency`` (Hz), the
    legs of a gait group in phase, the groups evenly staggered, the joints of a leg a quarter period apart. Each
    copy gets its own start phase and an amplitude between ``min_scale`` and 1 times ``amplitude``."""
    rng = np.random.default_rng(seed)
    t = np.arange(num_steps)[None, :] * CONTROL_TIMESTEP
    start = rng.uniform(0, 2 * np.pi, (num_robots, 1))
    scale = amplitude * rng.uniform(min_scale, 1.0, (num_robots, 1))
    group_of = {leg: i for i, group in enumerate(robot.gait_groups) for leg in group}
    targets = np.tile(np.asarray(robot.standing_pose, dtype=np.float64), (num_robots, num_steps, 1))
    joint = 0
    for leg in robot.legs:
        leg_phase = 2 * np.pi * group_of[leg.name] / len(robot.gait_groups)
        for k in range(len(leg.joints)):
            targets[..., joint] += scale * np.sin(2 * np.pi * frequency * t + start + leg_phase + k * np.pi / 2)
            joint += 1
    return targets

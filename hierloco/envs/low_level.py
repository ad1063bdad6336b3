"""The low-level interface of the latent-action environment: what turns one high-level action into N control steps
of joint targets on the batched simulator (Li et al., RA-L 2021, Sec. III-A: a low level at 100 Hz modulated by a
high-level action at about 1 Hz).

:class:`hierloco.envs.latent_env.LatentActionEnv` runs any :class:`LowLevel`; the low levels themselves (the latent
gait policy, expert replay, the Raibert controller) live in :mod:`hierloco.components.low_level`.

Example:
    >>> import numpy as np
    >>> from hierloco.envs.batched_sim import BatchedSimulator
    >>> from hierloco.envs.robots import get_robot
    >>> class Stand(LowLevel):  # one action: hold the standing pose for N = 100 steps
    ...     def __init__(self):
    ...         self.robot, self.steps_per_action = get_robot("a1"), 100
    ...         self.action_low, self.action_high = np.zeros(1), np.ones(1)
    ...     def run(self, sim, actions):
    ...         self._check(sim, actions)
    ...         return sim.run(np.tile(self.robot.standing_pose, (sim.num_robots, self.steps_per_action, 1)))
    >>> Stand().run(BatchedSimulator("a1", 2), np.zeros((2, 1))).com_state.shape  # B x N x 5
    (2, 100, 5)
"""

from __future__ import annotations

import numpy as np

from hierloco.envs.batched_sim import BatchedSimulator, SimulationResult
from hierloco.envs.robots import RobotSpec
from hierloco.registry import Registry

# The low levels by kind (what a run's ``run.json`` names): a new one is a :class:`LowLevel` subclass decorated with
# ``@LOW_LEVELS.register("kind")`` with a ``from_run`` classmethod that rebuilds it from a trained run's artifacts.
LOW_LEVELS = Registry("low_level", context=("run", "num_robots", "device"),
                      modules=("hierloco.components.low_level", "hierloco.components.sac_low_level"))


class LowLevel:
    """Base class: an action box ``action_low``/``action_high`` (``A``) and ``run``.

    ``num_choices`` is ``None`` for a continuous box and the number of actions for a finite set (then the action is
    a single index, ``A = 1``).
    """

    robot: RobotSpec
    steps_per_action: int
    action_low: np.ndarray
    action_high: np.ndarray
    num_choices: int | None = None
    kind: str = "low_level"

    @property
    def action_dim(self) -> int:
        return len(self.action_low)

    def run(self, sim: BatchedSimulator, actions: np.ndarray) -> SimulationResult:
        """Executes one action (``B x A``) on every copy of ``sim``; returns the ``B x N`` per-step result."""
        raise NotImplementedError

    @classmethod
    def from_run(cls, run, *, num_robots: int = 1, device: str = "cpu", **options) -> "LowLevel":
        """This low level as a trained run (:class:`hierloco.trained.TrainedRun`) recorded it: ``options`` are what
        the run's ``run.json`` holds under ``low_level.options``."""
        raise NotImplementedError(f"{cls.__name__} cannot be rebuilt from a run")

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Forgets any internal state for the copies in ``mask`` (default all); stateless low levels ignore it."""

    def action_features(self, actions):
        """The features a dynamics model sees for ``... x A`` actions (NumPy or torch): the actions themselves."""
        return actions

    def describe(self) -> dict:
        """What identifies this low level (stored with the data collected on it)."""
        return {"kind": self.kind, "robot": self.robot.name, "steps_per_action": self.steps_per_action,
                "action_low": np.asarray(self.action_low).tolist(), "action_high": np.asarray(self.action_high).tolist(),
                "num_choices": self.num_choices}

    def _check(self, sim: BatchedSimulator, actions: np.ndarray) -> np.ndarray:
        actions = np.asarray(actions, dtype=np.float64)
        if actions.shape != (sim.num_robots, self.action_dim):
            raise ValueError(f"actions must be B x A = {sim.num_robots} x {self.action_dim}, got {actions.shape}")
        if not np.all(np.isfinite(actions)):
            raise ValueError("actions contain NaN or inf")
        return actions

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
    # Control steps after which an action may be cut and the next begun without a break in the gait (a whole gait
    # period, for a low level whose joint targets repeat every period), or ``None``: only whole actions run.
    period_steps: int | None = None

    @property
    def action_dim(self) -> int:
        return len(self.action_low)

    def run(self, sim: BatchedSimulator, actions: np.ndarray) -> SimulationResult:
        """Executes one action (``B x A``) on every copy of ``sim``; returns the ``B x N`` per-step result."""
        raise NotImplementedError

    def run_steps(self, sim: BatchedSimulator, actions: np.ndarray, steps: int) -> SimulationResult:
        """The first ``steps`` control steps of one action (``B x A``) on every copy (``B x steps`` per-step result),
        ``steps`` whole gait periods (:attr:`period_steps`): what re-planning every ``steps`` control steps runs
        (:meth:`replan_problem` says which ``steps`` an env re-planning within a task step allows). A low level that
        can be cut overrides :meth:`_run_first`."""
        n = self.steps_per_action
        if steps == n:
            return self.run(sim, actions)
        if self.period_steps is None or isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) \
                or not 1 <= steps <= n or steps % self.period_steps:
            raise ValueError(f"an action of this low level can be cut only after whole gait periods of "
                             f"{self.period_steps} control steps (or not at all: None), got {steps!r}")
        return self._run_first(sim, actions, steps)

    def _run_first(self, sim: BatchedSimulator, actions: np.ndarray, steps: int) -> SimulationResult:
        raise NotImplementedError

    def replan_problem(self, steps) -> str | None:
        """Why an env cannot re-plan this low level's actions every ``steps`` control steps (``None``: it can):
        :func:`replan_problem` with its ``N`` and :attr:`period_steps`."""
        return replan_problem(steps, self.steps_per_action, self.period_steps)

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


def replan_problem(steps, steps_per_action: int, period_steps: int | None) -> str | None:
    """Why an env cannot re-plan actions of ``steps_per_action`` control steps (``N``) every ``steps`` (``None``: it
    can). ``steps`` must be ``N`` or whole gait periods of ``period_steps`` (``None``: the low level runs whole
    actions only) that divide ``N``, so that the re-planned actions of one task step fill it exactly.

        >>> replan_problem(20, 100, 20) is None, replan_problem(100, 100, None) is None
        (True, True)
        >>> replan_problem(40, 100, 20)
        "replan_steps must be whole gait periods of 20 control steps that divide the action's 100: one of [20, 100], got 40"
    """
    n = steps_per_action
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or not 1 <= steps <= n:
        return f"replan_steps must be a whole number of control steps in [1, {n}], got {steps!r}"
    if steps == n:
        return None
    if period_steps is None:
        return f"replan_steps must be null or {n}: this low level runs only whole actions of {n} control steps"
    if steps % period_steps or n % steps:
        allowed = [k for k in range(period_steps, n + 1, period_steps) if n % k == 0]
        return (f"replan_steps must be whole gait periods of {period_steps} control steps that divide the action's "
                f"{n}: one of {allowed}, got {steps}")
    return None

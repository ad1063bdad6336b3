"""TorchRL transforms for legged locomotion: the CoM state, disabled legs, and running a task on a high-level env
(:func:`task_transforms`: its episode index, step counter and reward) with the goal observation of a
goal-conditioned policy.

Example:
    >>> from hierloco.envs import make_env
    >>> env = make_env("a1", disabled_legs=("RR", "RL"))
    >>> td = env.rollout(3)
    >>> td["next", "com_state"].shape
    torch.Size([3, 5])
"""

from __future__ import annotations

from typing import Sequence

import torch
from tensordict import TensorDictBase
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs.transforms import Compose, StepCounter, Transform

from hierloco.envs.frames import world_to_local
from hierloco.envs.locomotion import LocomotionEnv
from hierloco.envs.robots import LOCK_PREFIX, RobotSpec, get_robot
from hierloco.envs.world_model import default_episodes


class CoMState(Transform):
    """Adds the CoM state from the base observations.

    Writes ``com_state`` = ``(x, y, yaw, vx, vy)`` in the world frame (m, rad, m/s) and ``com_velocity_local`` =
    ``(forward, left)`` velocity in the robot's local yaw frame (m/s), from ``com_position`` (``3``, world, m),
    ``orientation`` (``3``, roll/pitch/yaw, rad) and ``com_velocity`` (``3``, world, m/s).
    """

    def __init__(self, position_key="com_position", orientation_key="orientation", velocity_key="com_velocity",
                 out_keys: Sequence[str] = ("com_state", "com_velocity_local")):
        super().__init__(in_keys=[position_key, orientation_key, velocity_key], out_keys=list(out_keys))

    def _call(self, tensordict: TensorDictBase) -> TensorDictBase:
        position, orientation, velocity = (tensordict.get(key) for key in self.in_keys)
        yaw = orientation[..., 2]
        state = torch.cat([position[..., :2], yaw[..., None], velocity[..., :2]], -1)
        tensordict.set(self.out_keys[0], state)
        tensordict.set(self.out_keys[1], world_to_local(velocity[..., :2], yaw))
        return tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        like = observation_spec[self.in_keys[0]]
        batch = like.shape[:-1]
        observation_spec[self.out_keys[0]] = Unbounded(shape=(*batch, 5), dtype=like.dtype, device=like.device)
        observation_spec[self.out_keys[1]] = Unbounded(shape=(*batch, 2), dtype=like.dtype, device=like.device)
        return observation_spec


class DisableLegs(Transform):
    """Disables legs (the adverse setting of Li et al., RA-L 2021, Sec. IV-C): their joints are held at their standing
    angles.

    On the action side, the targets of the disabled joints are replaced by their standing angles, whatever the
    policy outputs. On reset, the joints are locked in the physics (a MuJoCo joint equality constraint), so they
    stay put under load, as a leg whose joints are fixed would. Works on any env built by
    :func:`hierloco.envs.make_env`.

    Args:
        robot: the robot (name or :class:`RobotSpec`).
        legs: the legs to disable (default: the robot's rear legs).
        action_key: the joint-target action.
    """

    def __init__(self, robot: str | RobotSpec, legs: Sequence[str] | None = None, action_key="action"):
        super().__init__(in_keys=[], out_keys=[], in_keys_inv=[action_key], out_keys_inv=[action_key])
        self.robot = get_robot(robot)
        self.legs = tuple(self.robot.rear_legs if legs is None else legs)
        index = torch.as_tensor(self.robot.leg_joint_indices(self.legs), device="cpu")
        self.register_buffer("joint_index", index)
        self.register_buffer("standing", torch.as_tensor(self.robot.standing_pose, dtype=torch.float32,
                                                         device="cpu")[index])

    def _inv_apply_transform(self, action: torch.Tensor) -> torch.Tensor:
        action = action.clone()
        action[..., self.joint_index] = self.standing.to(action.dtype)
        return action

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        physics = self._physics()
        model = physics.model.ptr
        joint_names = [self.robot.joint_names[i] for i in self.joint_index.tolist()]
        ids = [model.equality(f"{LOCK_PREFIX}{name}").id for name in joint_names]
        physics.data.eq_active[ids] = 1
        return tensordict_reset

    def _physics(self):
        env = self.parent.base_env if self.parent is not None else None
        if not isinstance(env, LocomotionEnv):
            raise RuntimeError("DisableLegs must sit on an env made by hierloco.envs.make_env (a LocomotionEnv), "
                               f"got {type(env).__name__}")
        return env.physics


class TaskEpisode(Transform):
    """Which target set (episode of ``task``) each robot pursues: ``task_episode`` (``B x 1``, int64), constant.

    On :class:`hierloco.envs.latent_env.LatentActionEnv` with ``B`` robots, robot ``b`` pursues episode
    ``episodes[b]`` (default ``b % task.num_episodes``, :func:`hierloco.envs.world_model.default_episodes`). Part of
    :func:`task_transforms`.

    Args:
        task: a :class:`hierloco.envs.tasks.Task`.
        episodes: ``B`` episode indices, or ``None``.
        out_key: where the episode index is written.
    """

    def __init__(self, task, episodes: Sequence[int] | None = None, out_key: str = "task_episode"):
        super().__init__(in_keys=[], out_keys=[out_key])
        self.task = task
        self.episodes = None if episodes is None else torch.as_tensor(episodes, dtype=torch.int64, device="cpu")

    def _episode_index(self, batch: torch.Size) -> torch.Tensor:
        count = batch.numel()
        episodes = self.episodes if self.episodes is not None else default_episodes(self.task, count)
        if episodes.numel() != count or episodes.min() < 0 or episodes.max() >= self.task.num_episodes:
            raise ValueError(f"episodes {episodes.tolist()} do not fit {count} robots and the task's "
                             f"{self.task.num_episodes} episodes")
        return episodes.reshape(*batch, 1)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        tensordict_reset.set(self.out_keys[0], self._episode_index(tensordict_reset.batch_size).to(
            tensordict_reset.device))
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        next_tensordict.set(self.out_keys[0], tensordict.get(self.out_keys[0]))
        return next_tensordict

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        observation_spec[self.out_keys[0]] = Unbounded((*observation_spec.shape, 1), dtype=torch.int64,
                                                       device=observation_spec.device)
        return observation_spec


class TaskReward(Transform):
    """The reward of a task: ``-task.cost`` of each transition, and its named terms (Li et al., RA-L 2021, Sec. IV-A).

    Reads the world-frame CoM state before and after the transition (``state_key``), ``task_episode`` and
    ``task_step`` (the task step the transition ends, 0-based, before the step counter advances). Writes
    ``reward`` (``B x 1``) and, per term of :meth:`hierloco.envs.tasks.Task.cost_terms`, ``cost_<term>``
    (``B x 1``, the term of the last transition, 0 after a reset). Part of :func:`task_transforms`.

    Args:
        task: a :class:`hierloco.envs.tasks.Task`.
        state_key, episode_key, step_key: the keys it reads.
    """

    def __init__(self, task, state_key: str = "com_state", episode_key: str = "task_episode",
                 step_key: str = "task_step"):
        self.term_keys = [f"cost_{term}" for term in task.cost_term_names]
        super().__init__(in_keys=[state_key, episode_key, step_key], out_keys=["reward", *self.term_keys])
        self.task = task

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        state_key, episode_key, step_key = self.in_keys
        terms = self.task.cost_terms(tensordict.get(state_key), next_tensordict.get(state_key),
                                     tensordict.get(episode_key).squeeze(-1), tensordict.get(step_key).squeeze(-1))
        dtype = next_tensordict.get("reward").dtype
        next_tensordict.set("reward", -self.task.total_cost(terms).unsqueeze(-1).to(dtype))
        for key, value in zip(self.term_keys, terms.values()):
            next_tensordict.set(key, value.unsqueeze(-1).to(dtype))
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        dtype = self.parent.full_reward_spec["reward"].dtype
        for key in self.term_keys:
            tensordict_reset.set(key, torch.zeros((*tensordict_reset.batch_size, 1), dtype=dtype,
                                                  device=tensordict_reset.device))
        return tensordict_reset

    def transform_output_spec(self, output_spec: Composite) -> Composite:
        output_spec = output_spec.clone()
        reward = output_spec["full_reward_spec", "reward"]
        for key in self.term_keys:  # per-transition values like the reward, kept with the observations
            output_spec["full_observation_spec", key] = Unbounded(reward.shape, dtype=reward.dtype,
                                                                  device=reward.device)
        return super().transform_output_spec(output_spec)


class TaskStepOfReplans(Transform):
    """The task step of an env that re-plans ``replans`` times per task step (a
    :class:`~hierloco.envs.latent_env.LatentActionEnv` with ``replan_steps = N / replans``): ``task_step`` (``B x 1``,
    int64) is the env steps counted so far (``env_step``, TorchRL's :class:`~torchrl.envs.transforms.StepCounter`)
    divided by ``replans``, rounded down, so a planner re-planning within a task step scores its plan against the
    targets of the task step it is in. Part of :func:`task_transforms` with ``replans > 1``.

    Example:
        >>> from torchrl.envs import TransformedEnv
        >>> from hierloco.components.gait_policy import train_gait_policy
        >>> from hierloco.components.low_level import LatentLowLevel
        >>> from hierloco.envs.latent_env import LatentActionEnv
        >>> from hierloco.envs.tasks import GoalReaching
        >>> from hierloco.envs.robots import get_robot
        >>> import numpy as np
        >>> standing = np.tile(get_robot("a1").standing_pose, (2, 100, 1))  # a toy gait: two periods of standing
        >>> trained = train_gait_policy(standing, hidden=8, epochs=1, progress=False, periods_per_action=2)
        >>> env = LatentActionEnv(LatentLowLevel(trained, "a1"), num_robots=2, replan_steps=50)
        >>> env = TransformedEnv(env, task_transforms(GoalReaching(num_goals=2, num_steps=2), replans=2))
        >>> td = env.rollout(4, break_when_any_done=False)
        >>> td["next", "task_step"][0].squeeze(-1).tolist(), td["next", "truncated"][0].squeeze(-1).tolist()
        ([0, 1, 1, 2], [False, False, False, True])
    """

    def __init__(self, replans: int, in_key: str = "env_step", out_key: str = "task_step"):
        super().__init__(in_keys=[in_key], out_keys=[out_key])
        self.replans = int(replans)

    def _task_step(self, tensordict: TensorDictBase) -> TensorDictBase:
        tensordict.set(self.out_keys[0], torch.div(tensordict.get(self.in_keys[0]), self.replans,
                                                   rounding_mode="floor"))
        return tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._task_step(tensordict_reset)

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._task_step(next_tensordict)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        observation_spec[self.out_keys[0]] = Unbounded((*observation_spec.shape, 1), dtype=torch.int64,
                                                       device=observation_spec.device)
        return observation_spec


def task_transforms(task, episodes: Sequence[int] | None = None, *, state_key: str = "com_state",
                    replans: int = 1) -> Compose:
    """Runs ``task`` on a high-level env (one step per task step): its task state, its reward and its time limit.

    ``Compose(TaskEpisode(task, episodes), StepCounter(task.num_steps, step_count_key="task_step"),
    TaskReward(task))``: ``task_episode`` says which target set each robot pursues, ``task_step`` counts the task
    steps done (TorchRL's :class:`~torchrl.envs.transforms.StepCounter`: 0 at a reset, kept across a partial reset
    for the robots not reset, and ``truncated``/``done`` set once it reaches ``task.num_steps``), ``reward`` is
    ``-task.cost``. With ``replans > 1`` (an env that re-plans that many times per task step), ``env_step`` counts
    the env's steps, ``task_step`` the task steps (:class:`TaskStepOfReplans`), and no reward is written: a task's
    cost is defined per task step, and :func:`hierloco.components.evaluation.run_task` scores the task's own steps.

    Example:
        >>> from torchrl.envs import TransformedEnv
        >>> from hierloco.components.expert_library import build_expert_library
        >>> from hierloco.components.low_level import ExpertReplayLowLevel
        >>> from hierloco.envs.latent_env import LatentActionEnv
        >>> from hierloco.envs.tasks import GoalReaching
        >>> task = GoalReaching(num_goals=2, num_steps=3)
        >>> low = ExpertReplayLowLevel(build_expert_library("daisy", 3, progress=False))
        >>> env = TransformedEnv(LatentActionEnv(low, num_robots=2), task_transforms(task))
        >>> td = env.rollout(5, break_when_any_done=False)
        >>> td["next", "task_step"].squeeze(-1).tolist(), td["next", "truncated"][0].squeeze(-1).tolist()
        ([[1, 2, 3, 1, 2], [1, 2, 3, 1, 2]], [False, False, True, False, False])
    """
    if replans > 1:  # re-planning within each task step: the costs are the task's, on its own steps (run_task)
        return Compose(TaskEpisode(task, episodes), StepCounter(max_steps=task.num_steps * replans,
                                                                step_count_key="env_step"),
                       TaskStepOfReplans(replans))
    return Compose(TaskEpisode(task, episodes), StepCounter(max_steps=task.num_steps, step_count_key="task_step"),
                   TaskReward(task, state_key=state_key))


def TaskTransform(task, episodes: Sequence[int] | None = None, state_key: str = "com_state") -> Compose:  # noqa: N802
    """Deprecated name of :func:`task_transforms`, kept for existing callers."""
    return task_transforms(task, episodes, state_key=state_key)


class ContinueAfterFalls(Transform):
    """Evaluation episodes that run their full length: a robot that falls (or whose physics blows up) is not reset
    but keeps being simulated and scored, and the fall is recorded instead of ending its episode.

    Moves the base env's ``terminated`` into ``fallen`` (``B x 1`` bool, true from the step the robot failed until
    the next reset) and clears ``terminated`` (``done`` keeps only the truncation), so that
    ``env.rollout(..., break_when_any_done=False)`` never resets a fallen robot mid-episode. Sits first, right on
    the base env. Not for training: a collector would never reset a fallen robot.

    Args:
        out_key: where the fall flag is written.
    """

    def __init__(self, out_key: str = "fallen"):
        super().__init__(in_keys=["terminated"], out_keys=[out_key])

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        fallen = torch.zeros((*tensordict_reset.batch_size, 1), dtype=torch.bool, device=tensordict_reset.device)
        if tensordict is not None and "_reset" in tensordict.keys() and self.out_keys[0] in tensordict.keys():
            fallen = tensordict.get(self.out_keys[0]) & ~tensordict.get("_reset")
        tensordict_reset.set(self.out_keys[0], fallen)
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        terminated = next_tensordict.get("terminated")
        next_tensordict.set(self.out_keys[0], tensordict.get(self.out_keys[0]) | terminated)
        next_tensordict.set("terminated", torch.zeros_like(terminated))
        next_tensordict.set("done", next_tensordict.get("truncated").clone())
        return next_tensordict

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        observation_spec[self.out_keys[0]] = Categorical(2, (*observation_spec.shape, 1), dtype=torch.bool,
                                                         device=observation_spec.device)
        return observation_spec


class GoalObservation(Transform):
    """The observation of a goal-conditioned policy (SAC's high level), from the CoM and task state.

    Writes ``goal_observation`` (``... x 7``): the task's target in the robot's local frame
    (:meth:`hierloco.envs.tasks.Task.relative_target`, ``2``), the CoM velocity in the local frame (``2``), the sine
    and cosine of the yaw error to the task's yaw target (``2``) and the fraction of the episode done (``1``).
    Sits after the :func:`task_transforms` of the same task.
    """

    SIZE = 7

    def __init__(self, task, state_key: str = "com_state", out_key: str = "goal_observation"):
        super().__init__(in_keys=[state_key, "task_episode", "task_step"], out_keys=[out_key])
        self.task = task

    def _call(self, tensordict: TensorDictBase) -> TensorDictBase:
        state = tensordict.get(self.in_keys[0])
        episode = tensordict.get("task_episode").squeeze(-1)
        step = tensordict.get("task_step").squeeze(-1)
        target = self.task.relative_target(state, episode, step).to(state.dtype)
        velocity = world_to_local(state[..., 3:5], state[..., 2])
        yaw_error = self.task.start_yaw - state[..., 2]
        progress = (step.to(state.dtype) / self.task.num_steps)[..., None]
        features = torch.cat([target, velocity, torch.sin(yaw_error)[..., None], torch.cos(yaw_error)[..., None],
                              progress], -1)
        tensordict.set(self.out_keys[0], features)
        return tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._call(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        like = observation_spec[self.in_keys[0]]
        observation_spec[self.out_keys[0]] = Unbounded((*like.shape[:-1], self.SIZE), dtype=like.dtype,
                                                       device=like.device)
        return observation_spec

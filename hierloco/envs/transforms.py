"""TorchRL transforms for legged locomotion: the CoM state and disabled legs.

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
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from hierloco.envs.frames import world_to_local
from hierloco.envs.robots import LOCK_PREFIX, RobotSpec, get_robot


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
    """Disables legs (the adverse setting of SPEC 7): their joints are held at their standing angles.

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
        index = torch.as_tensor(self.robot.leg_joint_indices(self.legs))
        self.register_buffer("joint_index", index)
        self.register_buffer("standing", torch.as_tensor(self.robot.standing_pose, dtype=torch.float32)[index])

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
        physics = getattr(getattr(env, "_env", None), "physics", None)
        if physics is None:
            raise RuntimeError("DisableLegs must sit on an env made by hierloco.envs.make_env (a dm_control env)")
        return physics

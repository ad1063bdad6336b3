"""The latent-action layer over any TorchRL env whose action is the joint-target vector (Li et al., RA-L 2021,
Sec. III-A: one latent action z, held for N control steps at 100 Hz, is turned into joint targets by the gait policy
``pi(t, z)``).

:class:`LatentActionWrapper` wraps such an env, e.g. ``make_env("a1")`` (:func:`hierloco.envs.make_env`) or a
user's env with its own transforms: its action is a latent ``z`` in the latent box and one of its steps runs the
low level for N control steps of the wrapped env, with phases ``t = n / N`` for ``n = 1..N``, exactly as
:class:`hierloco.envs.latent_env.LatentActionEnv` does on the batched simulator. That batched simulator stays the fast
path (B robots through ``mujoco.rollout``, no Python per control step); this layer is the general one (any env, any
transforms, one Python step per control step).

A step returns the wrapped env's observations at the end of the action, its rewards summed over the action, and its
done flags. When the wrapped env's episode ends during an action (a fall, the time limit) the action stops there:
with a batch of robots it goes on while any robot's episode goes on, and the robots that are done keep the
observations, flags and reward of the control step at which they ended (the wrapped env must accept steps of rows
that are done, as TorchRL envs without checks do).

Example:
    >>> import numpy as np
    >>> from torchrl.envs.utils import check_env_specs
    >>> from hierloco.components.gait_policy import train_gait_policy
    >>> from hierloco.components.low_level import LatentLowLevel
    >>> from hierloco.envs import get_robot, make_env
    >>> standing = np.tile(get_robot("a1").standing_pose, (2, 100, 1))  # two "experts" that stand still
    >>> trained = train_gait_policy(standing, hidden=8, epochs=20, progress=False)
    >>> env = LatentActionWrapper(make_env("a1", seed=0), LatentLowLevel(trained, "a1"))
    >>> env.action_spec.shape, env.steps_per_action
    (torch.Size([3]), 100)
    >>> td = env.rollout(2)
    >>> td["next", "com_state"].shape  # the CoM state at the end of each latent action
    torch.Size([2, 5])
"""

from __future__ import annotations

from typing import Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded
from torchrl.envs import EnvBase
from torchrl.envs.utils import step_mdp


class LatentActionWrapper(EnvBase):
    """Holds one latent action for N control steps of a joint-target env, through a low level.

    Args:
        env: a TorchRL env (batch ``B``, possibly empty) whose action (``env.action_key``) is the joint targets.
        low_level: a :class:`hierloco.components.low_level.LatentLowLevel` (its :meth:`as_module`, latent box and N
            are used), or any TensorDict module reading ``latent_key`` (``B x Z``) and ``phase_key`` (``B x 1``) and
            writing the wrapped env's action (then give ``steps_per_action``, ``action_low`` and ``action_high``).
        steps_per_action: N, control steps per latent action.
        action_low, action_high: the latent box (``Z``).
        latent_key, phase_key: where the latent and the phase are written in the wrapped env's TensorDicts for the
            low level to read.

    The action spec is the latent box (``B x Z``); observations, reward and done specs are the wrapped env's. The
    construction calls the low level once on the box's centre and refuses (``ValueError``) a low level that cannot
    take a latent of the box's size or does not write the wrapped env's action in the shape of its action spec (a
    low level of another robot). A low level whose network is on another device than the env
    (``run.low_level(device="cuda")``) runs there: the latent and the phase go over and the joint targets come back
    at every control step.
    """

    def __init__(self, env: EnvBase, low_level, *, steps_per_action: int | None = None,
                 action_low: Sequence[float] | None = None, action_high: Sequence[float] | None = None,
                 latent_key: str = "latent", phase_key: str = "phase"):
        if hasattr(low_level, "as_module"):
            steps_per_action = low_level.steps_per_action if steps_per_action is None else steps_per_action
            action_low = low_level.action_low if action_low is None else action_low
            action_high = low_level.action_high if action_high is None else action_high
            low_level = low_level.as_module(latent_key=latent_key, phase_key=phase_key, out_key=env.action_key)
        if steps_per_action is None or action_low is None or action_high is None:
            raise ValueError("give steps_per_action, action_low and action_high with a low level that is a module")
        if isinstance(steps_per_action, bool) or int(steps_per_action) != steps_per_action or steps_per_action < 1:
            raise ValueError(f"steps_per_action must be a whole number of control steps >= 1, got {steps_per_action}")
        low = torch.as_tensor(action_low, dtype=torch.float32, device="cpu")
        high = torch.as_tensor(action_high, dtype=torch.float32, device="cpu")
        if low.ndim != 1 or low.shape != high.shape or not torch.all(low <= high):
            raise ValueError(f"bad latent box: low {action_low}, high {action_high}")
        super().__init__(batch_size=env.batch_size, device=env.device)
        self.env = env
        self.low_level = low_level
        parameters = low_level.parameters() if isinstance(low_level, torch.nn.Module) else iter(())
        self._low_level_device = next((p.device for p in parameters), None)
        self.steps_per_action = int(steps_per_action)
        self.latent_key, self.phase_key = latent_key, phase_key
        batch = tuple(env.batch_size)
        self.action_spec = Bounded(low.expand(*batch, -1), high.expand(*batch, -1), (*batch, len(low)),
                                   device=self.device)
        self.observation_spec = env.observation_spec.clone()
        self.reward_spec = env.full_reward_spec.clone()
        self.done_spec = env.full_done_spec.clone()
        self._inner: TensorDictBase | None = None  # the wrapped env's current TensorDict
        self._check_low_level(low, high)

    def _check_low_level(self, low: torch.Tensor, high: torch.Tensor) -> None:
        """At construction, one call of the low level on the latent box's centre: a ``ValueError`` unless it takes a
        latent of the box's size and writes the wrapped env's action with the shape of its action spec."""
        key = self.env.action_key
        expected = tuple(self.env.full_action_spec[key].shape)
        batch = tuple(self.env.batch_size)
        probe = TensorDict({self.latent_key: ((low + high) / 2).expand(*batch, -1),
                            self.phase_key: torch.full((*batch, 1), 1.0 / self.steps_per_action, device="cpu")},
                           batch_size=batch).to(self.env.device or "cpu")
        try:
            with torch.no_grad():
                targets = self._joint_targets(probe).get(key)
        except (RuntimeError, ValueError, KeyError, IndexError, TypeError) as error:
            raise ValueError(f"the low level fails on a latent of the box's size {len(low)} (latent box {low.tolist()} "
                             f"to {high.tolist()}): {error}") from None
        if tuple(targets.shape) != expected:
            raise ValueError(f"the low level writes {key!r} of shape {tuple(targets.shape)}, the wrapped env's action "
                             f"spec has shape {expected} (a low level of another robot?)")

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        inner = self.env.reset(tensordict.select(*self.env.reset_keys, strict=False)
                               if tensordict is not None else None)
        self._inner = inner
        return inner.select(*self.observation_spec.keys(True, True), *self.full_done_spec.keys(True, True),
                            strict=False)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        if self._inner is None:
            raise RuntimeError("reset the env before stepping it")
        latent = tensordict.get(self.action_key)
        batch = self.batch_size
        inner, out, finished, reward = self._inner, None, None, None
        reward_keys = list(self.full_reward_spec.keys(True, True))
        keys = [*self.observation_spec.keys(True, True), *self.full_done_spec.keys(True, True), *reward_keys]
        for n in range(1, self.steps_per_action + 1):
            inner.set(self.latent_key, latent)
            inner.set(self.phase_key, torch.full((*batch, 1), n / self.steps_per_action, device=latent.device))
            inner = self.env.step(self._joint_targets(inner))
            now = inner.get("next").select(*keys, strict=False)
            done = (now.get("done").reshape(batch) if "done" in now.keys()
                    else torch.zeros(batch, dtype=torch.bool, device=latent.device))
            if out is None:
                out, finished = now.clone(), done.clone()
                reward = {key: now.get(key).clone() for key in reward_keys}
            else:
                going = ~finished
                out = out.apply(lambda old, new: torch.where(_rows(going, new), new, old), now)
                for key in reward_keys:
                    reward[key] = reward[key] + torch.where(_rows(going, now.get(key)), now.get(key), 0)
                finished = finished | done
            inner = step_mdp(inner, exclude_action=False, keep_other=True)
            if bool(finished.all()):
                break
        self._inner = inner
        for key, value in reward.items():
            out.set(key, value)
        return out

    def _joint_targets(self, inner: TensorDictBase) -> TensorDictBase:
        """The low level on ``inner``, on the low level's device when it is not the env's."""
        device = self._low_level_device
        if device is None or inner.device in (None, device):
            return self.low_level(inner)
        acted = self.low_level(inner.select(self.latent_key, self.phase_key).to(device))
        return inner.set(self.env.action_key, acted.get(self.env.action_key).to(inner.device))

    def _set_seed(self, seed: int | None) -> None:
        self.env.set_seed(seed)

    def close(self, *, raise_if_closed: bool = True) -> None:
        self.env.close(raise_if_closed=raise_if_closed)
        super().close(raise_if_closed=raise_if_closed)


def _rows(mask: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """``mask`` (the batch shape) with trailing singleton dimensions to broadcast against ``like``."""
    return mask.reshape(*mask.shape, *([1] * (like.ndim - mask.ndim)))


__all__ = ["LatentActionWrapper"]

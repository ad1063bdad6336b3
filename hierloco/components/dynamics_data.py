"""CoM dynamics data: random high-level actions chained on B robots, collected with a TorchRL collector (Li et al.,
RA-L 2021, Sec. III-C and Algorithm 1).

Each action is drawn uniformly from the low level's action space (the latent box for LAT, the expert indices for
LIB, the command box for IK), held for one action (N control steps), and actions are chained; an episode is reset
after ``episode_length`` actions and whenever a robot falls. Transitions during which a robot fell or the physics
blew up are counted and dropped: they never reach the model.

Example:
    >>> from hierloco.components.expert_library import build_expert_library
    >>> from hierloco.components.low_level import ExpertReplayLowLevel
    >>> from hierloco.envs.latent_env import LatentActionEnv
    >>> env = LatentActionEnv(ExpertReplayLowLevel(build_expert_library("daisy", 3, progress=False)), num_robots=4)
    >>> data = collect_transitions(env, 8, seed=0, progress=False)
    >>> data.com_state.shape, data.action.shape
    ((8, 5), (8, 1))
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.data import Categorical
from tqdm.auto import tqdm

from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.robots.spec import CONTROL_TIMESTEP
from hierloco.errors import Finding
from hierloco.io import ArtifactError, load_arrays, save_arrays


MIN_ACTIONS_JUDGED = 200  # random actions executed before a setting where (nearly) every one falls is given up
FALL_LIMIT = 0.95


class DynamicsDataError(Finding, RuntimeError):
    """Nearly every random action ends in a fall: the setting leaves the low level nothing to learn from."""


class UniformActionPolicy(TensorDictModuleBase):
    """Writes ``action`` drawn uniformly from ``action_spec`` (box or finite set), from its own seeded generator."""

    def __init__(self, action_spec, seed: int = 0):
        super().__init__()
        self.in_keys, self.out_keys = [], ["action"]
        self.action_spec = action_spec
        self.generator = torch.Generator().manual_seed(seed)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        spec = self.action_spec
        shape = tensordict.batch_size + spec.shape[len(tensordict.batch_size):]
        if isinstance(spec, Categorical):
            action = torch.randint(spec.n, shape, generator=self.generator, dtype=spec.dtype, device="cpu")
        else:
            low, high = spec.space.low.cpu(), spec.space.high.cpu()
            action = low + (high - low) * torch.rand(shape, generator=self.generator, device="cpu")
        return tensordict.set("action", action.to(spec.device))


@dataclass
class TransitionData:
    """M transitions ``(com_state, action) -> next_com_state``, world frame ``(x, y, yaw, vx, vy)``; ``body_state``
    (``M x 3``: roll, pitch in rad, the base's height above the ground in m at each action's start, what the trunk
    felt of the ground; ``None`` in data collected before it was recorded)."""

    com_state: np.ndarray
    action: np.ndarray
    next_com_state: np.ndarray
    metadata: dict = field(default_factory=dict)
    body_state: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.com_state)

    def save(self, path: str | os.PathLike) -> None:
        arrays = {"com_state": self.com_state, "action": self.action, "next_com_state": self.next_com_state}
        if self.body_state is not None:
            arrays["body_state"] = self.body_state
        save_arrays(path, arrays, {**self.metadata, "kind": "transitions"})

    def achievable_speeds(self, percentile: float = 95.0) -> dict[str, float]:
        """What the robot can still do under this data's low level and setting (e.g. a fault): the ``percentile`` of
        its speed over the transitions in each direction of the local frame at each action's start, ``forward``,
        ``backward``, ``left``, ``right`` (m/s), and of its turning rate ``turn`` (|yaw rate|, rad/s). An action
        lasts ``metadata["low_level"]["steps_per_action"]`` control steps of 0.01 s.

            >>> state = np.zeros((2, 5)); state[:, 2] = np.pi / 2          # facing +y
            >>> moved = state.copy(); moved[:, 1] = [0.3, -0.1]            # 0.3 m forward, 0.1 m back in 1 s
            >>> data = TransitionData(state, np.zeros((2, 1)), moved, {"low_level": {"steps_per_action": 100}})
            >>> {k: round(v, 2) for k, v in data.achievable_speeds(percentile=100).items()}
            {'forward': 0.3, 'backward': 0.1, 'left': 0.0, 'right': 0.0, 'turn': 0.0}
        """
        from hierloco.components.com_model import local_transition

        try:
            seconds = int(self.metadata["low_level"]["steps_per_action"]) * CONTROL_TIMESTEP
        except (KeyError, TypeError, ValueError):
            raise ValueError("achievable_speeds: the data's metadata names no low_level.steps_per_action") from None
        _, delta = local_transition(self.com_state, self.next_com_state)
        dx, dy, dyaw = (delta[:, i].numpy() / seconds for i in range(3))
        at = lambda values: float(np.percentile(values, percentile))  # noqa: E731
        return {"forward": at(dx), "backward": at(-dx), "left": at(dy), "right": at(-dy), "turn": at(np.abs(dyaw))}

    def summary(self) -> dict:
        """What a run's ``report.json`` keeps of this data (and so a study's job record): the ``metadata`` and the
        :meth:`achievable_speeds`."""
        return {**self.metadata, "achievable_speeds": self.achievable_speeds()}

    @classmethod
    def load(cls, path: str | os.PathLike) -> "TransitionData":
        arrays, metadata = load_arrays(path)
        names = {"com_state", "action", "next_com_state"}
        if metadata.pop("kind", None) != "transitions" or not names <= set(arrays) <= names | {"body_state"}:
            raise ArtifactError(f"{path} is not a transitions file")
        return cls(**arrays, metadata=metadata)


def collect_transitions(env: LatentActionEnv, num_transitions: int, *, episode_length: int = 20, seed: int = 0,
                        progress: bool = False) -> TransitionData:
    """Collects ``num_transitions`` valid transitions on ``env`` with uniformly random actions.

    ``metadata`` records the low level, the seed, how many transitions were dropped for falls or blow-ups, and how
    many actions were executed in all.
    """
    if int(num_transitions) < 1:
        raise ValueError(f"num_transitions must be positive, got {num_transitions}")
    if int(episode_length) < 1:
        raise ValueError(f"episode_length must be positive, got {episode_length}")
    env.set_seed(seed)
    num_robots = env.batch_size[0]
    collector = Collector(env, UniformActionPolicy(env.action_spec, seed), frames_per_batch=num_robots,
                          total_frames=-1, max_frames_per_traj=int(episode_length), reset_at_each_iter=False,
                          auto_register_policy_transforms=False)
    states, actions, next_states, bodies = [], [], [], []
    kept = dropped = 0
    bar = tqdm(total=int(num_transitions), desc=f"dynamics data ({env.robot.name})", disable=not progress)
    try:
        for batch in collector:
            batch = batch.reshape(-1)
            valid = ~batch["next", "terminated"].reshape(-1)
            dropped += int((~valid).sum())
            take = min(int(valid.sum()), int(num_transitions) - kept)
            if take:
                index = torch.nonzero(valid).reshape(-1)[:take]
                states.append(batch["com_state"][index])
                actions.append(batch["action"][index].reshape(take, -1).to(torch.float32))
                next_states.append(batch["next", "com_state"][index])
                if "body_state" in batch.keys():  # an env that reports it (LatentActionEnv)
                    bodies.append(batch["body_state"][index])
            kept += take
            bar.update(take)
            if kept >= num_transitions:
                break
            executed = kept + dropped
            if (dropped > 10 * int(num_transitions) + 10 * num_robots
                    or (executed >= max(MIN_ACTIONS_JUDGED, 5 * num_robots) and dropped > FALL_LIMIT * executed)):
                raise DynamicsDataError(f"{env.robot.name}: {dropped} of {executed} random actions ended in a fall or "
                                        f"a blow-up (disabled legs {list(env.sim.disabled_legs)}, limp legs "
                                        f"{list(env.sim.limp_legs)}): the low level cannot produce usable dynamics "
                                        "data in this setting")
    finally:
        collector.shutdown()
        bar.close()
    metadata = {"low_level": env.low_level.describe(), "seed": int(seed), "episode_length": int(episode_length),
                "num_robots": int(num_robots), "dropped_failures": dropped, "actions_executed": kept + dropped,
                "disabled_legs": list(env.sim.disabled_legs), "limp_legs": list(env.sim.limp_legs)}
    return TransitionData(torch.cat(states).double().numpy(), torch.cat(actions).double().numpy(),
                          torch.cat(next_states).double().numpy(), metadata,
                          torch.cat(bodies).double().numpy() if len(bodies) == len(states) else None)

"""The latent-action layer over a 100 Hz TorchRL env (Li et al., RA-L 2021, Sec. III-A: a latent held for N control
steps through the gait policy): TorchRL contracts over ``make_env``, the same CoM transitions as the batched
simulator's :class:`LatentActionEnv`, user transforms below it, early ends, and ``make_env``'s flat observation."""

import numpy as np
import pytest
import torch
from tensordict.nn import TensorDictModule
from torchrl.envs import StepCounter
from torchrl.envs.utils import check_env_specs

from hierloco.components.expert_library import build_expert_library
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.envs import make_env
from hierloco.envs.latent_env import LatentActionEnv
from hierloco.envs.latent_wrapper import LatentActionWrapper
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.envs.torchrl_env import OBSERVATION_KEYS

ROBOT = "daisy"
TOLERANCE = 1e-5  # m, rad, m/s: float32 rounding (measured 1.3e-7 over 5 actions on A1), far below any gait effect


@pytest.fixture(scope="module")
def low_level():
    library = build_expert_library(ROBOT, 3, seed=0, settle_time=1.0, progress=False)
    periods = int(round(library.steps_per_action * CONTROL_TIMESTEP / get_robot(ROBOT).gait_period))
    trained = train_gait_policy(library.joint_targets, latent_dim=2, periods_per_action=periods, hidden=64,
                                epochs=100, batch_size=300, lr=3e-3, progress=False)  # walks: expert 1 at 0.4 m/s
    return LatentLowLevel(trained, ROBOT)


def test_check_env_specs_over_make_env(low_level):
    env = LatentActionWrapper(make_env(ROBOT, seed=0), low_level)
    check_env_specs(env)
    assert env.action_spec.shape == (2,) and env.steps_per_action == 100
    torch.testing.assert_close(env.action_spec.space.low, torch.as_tensor(low_level.action_low, dtype=torch.float32))


def test_same_com_transitions_as_the_batched_simulator(low_level):
    """The same latents from the same start (no reset noise): the CoM state after each of 4 actions agrees with
    :class:`LatentActionEnv` within TOLERANCE, and the robot moved (the comparison is not trivially at rest)."""
    latents = torch.as_tensor(low_level.trained.latents)[[1, 0, 2, 1]].float()
    fast = LatentActionEnv(low_level, num_robots=1, init_joint_noise=0.0, seed=0)
    layered = LatentActionWrapper(make_env(ROBOT, init_joint_noise=0.0, seed=0), low_level)
    fast_td, layered_td = fast.reset(), layered.reset()
    torch.testing.assert_close(layered_td["com_state"], fast_td["com_state"][0], atol=TOLERANCE, rtol=0)
    travelled = 0.0
    for z in latents:
        before = fast_td["com_state"][0, :2].clone()
        fast_td = fast.step(fast_td.set("action", z[None]))["next"]
        layered_td = layered.step(layered_td.set("action", z))["next"]
        torch.testing.assert_close(layered_td["com_state"], fast_td["com_state"][0], atol=TOLERANCE, rtol=0)
        assert not layered_td["done"].item() and layered_td["reward"].item() == pytest.approx(100.0)  # upright
        travelled += float((fast_td["com_state"][0, :2] - before).norm())
    assert travelled > 0.5, travelled
    fast.close()


def test_a_users_transforms_stay_below_the_layer(low_level):
    """A transform of the 100 Hz env (a step counter) sees every control step: 100 per latent action."""
    env = LatentActionWrapper(make_env(ROBOT, seed=0).append_transform(StepCounter()), low_level)
    td = env.rollout(2)
    assert td["next", "step_count"].squeeze(-1).tolist() == [100, 200]


def test_an_episode_that_ends_during_an_action_ends_the_action():
    """A low level that sends every joint to zero: A1 falls within the first action; the step stops at the fall
    (fewer than N control steps), terminated, with the reward of the steps before it."""
    def collapse(latent, phase):
        return torch.zeros(*latent.shape[:-1], 12)

    low = TensorDictModule(collapse, in_keys=["latent", "phase"], out_keys=["action"])
    env = LatentActionWrapper(make_env("a1", seed=0).append_transform(StepCounter()), low, steps_per_action=100,
                              action_low=[-1.0], action_high=[1.0])
    td = env.rollout(3)
    assert td.batch_size == (1,) and td["next", "terminated"].item()
    steps = td["next", "step_count"].item()
    assert 1 <= steps < 100
    assert td["next", "reward"].item() == pytest.approx(steps - 1)  # 1 per upright step, 0 at the fall


def test_make_env_flat_observation_is_the_documented_concatenation():
    env = make_env("a1", seed=0)
    td = env.rollout(3)
    robot = get_robot("a1")
    assert OBSERVATION_KEYS == ("com_position", "com_velocity", "orientation", "joint_positions",
                                "joint_velocities", "foot_contacts")
    assert td["observation"].shape == (3, 9 + 2 * robot.num_joints + len(robot.legs))
    for root in (td, td["next"]):
        torch.testing.assert_close(root["observation"], torch.cat([root[key] for key in OBSERVATION_KEYS], -1))
    assert env.observation_spec["observation"].shape == (37,)

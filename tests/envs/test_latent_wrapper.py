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
        parts = [root[key].float() for key in OBSERVATION_KEYS]  # foot contacts: bool under their own key
        torch.testing.assert_close(root["observation"], torch.cat(parts, -1))
    assert env.observation_spec["observation"].shape == (37,)


def test_foot_contacts_are_bool_under_their_own_key_and_0_1_in_the_flat_observation(low_level):
    """The dtype convention of ``hierloco.envs``, in ``make_env`` and in the latent layer over it, as in the batched
    simulator's ``LatentActionEnv(record=True)``; the flat observation stays float32."""
    for env in (make_env("a1", seed=0), LatentActionWrapper(make_env(ROBOT, seed=0), low_level)):
        check_env_specs(env)
        assert env.observation_spec["foot_contacts"].dtype == torch.bool
        td = env.rollout(2)["next"]
        contacts = td["foot_contacts"]
        assert contacts.dtype == torch.bool and td["observation"].dtype == torch.float32
        assert torch.equal(td["observation"][..., -contacts.shape[-1]:], contacts.float())
        assert contacts[-1].any(), "a standing robot has feet on the ground"


def test_a_low_level_that_does_not_fit_is_refused_at_construction(low_level):
    """The action spec is checked when the layer is built, in one ValueError, before any step: a low level of
    another robot (Daisy's 18 joints over A1's 12), or a latent box of another size than the low level's latent."""
    with pytest.raises(ValueError, match=r"writes 'action' of shape \(18,\), the wrapped env's action spec has "
                                         r"shape \(12,\)"):
        LatentActionWrapper(make_env("a1", seed=0), low_level)
    with pytest.raises(ValueError, match="the low level fails on a latent of the box's size 3"):
        LatentActionWrapper(make_env(ROBOT, seed=0), low_level, action_low=[-1.0] * 3, action_high=[1.0] * 3)

"""The components as TensorDict modules with declared keys: the low level, the gait policy, the CoM models and the
planners compose in a TensorDictSequential and export with torch.export (Li et al., RA-L 2021, Sec. III)."""

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from tensordict.nn import TensorDictSequential

from hierloco.components.com_ensemble import CoMEnsembleModel
from hierloco.components.com_model import CoMDynamicsModel, com_model_module
from hierloco.components.gait_policy import train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.components.planners import BoxCEMPlanner
from hierloco.envs.robots import get_robot
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv


@pytest.fixture(scope="module")
def low_level():
    """A tiny gait policy fitted to two made-up periodic patterns of A1's joints (the module contracts, not gaits)."""
    phase = np.arange(1, 101) / 100
    standing = np.asarray(get_robot("a1").standing_pose)
    patterns = np.stack([standing + 0.1 * np.sin(2 * np.pi * 5 * phase + k)[:, None] for k in (0.0, 1.0)])
    return LatentLowLevel(train_gait_policy(patterns, latent_dim=2, periods_per_action=5, hidden=32, epochs=30,
                                            progress=False), "a1")


def test_low_level_module_is_the_policy_at_each_phase(low_level):
    """``latent`` + ``phase`` -> ``action``: step n of the module (phase n / N) is step n of the whole pattern."""
    module = low_level.as_module()
    assert module.in_keys == ["latent", "phase"] and module.out_keys == ["action"]
    z = torch.as_tensor(low_level.trained.latents)
    pattern = torch.as_tensor(low_level.patterns(z.numpy()))
    for n in (1, 37, 100):
        td = module(TensorDict({"latent": z, "phase": torch.full((2, 1), n / 100)}, [2]))
        torch.testing.assert_close(td["action"].double(), pattern[:, n - 1], atol=1e-6, rtol=0)
    # outside the latent box the latent is clipped to it
    far = z + 100.0
    clipped = torch.as_tensor(low_level.action_high, dtype=torch.float32).expand(2, -1)
    phase = torch.full((2, 1), 0.5)
    torch.testing.assert_close(module(TensorDict({"latent": far, "phase": phase}, [2]))["action"],
                               module(TensorDict({"latent": clipped, "phase": phase}, [2]))["action"])


def test_gait_policy_modules(low_level):
    policy = low_level.policy
    z = torch.as_tensor(low_level.trained.latents)
    pattern = policy.pattern_module()(TensorDict({"latent": z}, [2]))["joint_pattern"]
    torch.testing.assert_close(pattern, policy.pattern(z))
    step = policy.as_module()(TensorDict({"latent": z, "phase": torch.full((2, 1), 0.2)}, [2]))["joint_targets"]
    torch.testing.assert_close(step, pattern[:, 19])


@pytest.mark.parametrize("model", [CoMDynamicsModel(action_dim=2, hidden=16),
                                   CoMEnsembleModel(action_dim=2, hidden=16, members=3)])
def test_planner_then_model_in_a_sequence(model):
    """A planner and the CoM model module in one TensorDictSequential: the plan's action, then the model's predicted
    next state (and, for the ensemble, its members and their spread)."""
    env = CoMWorldModelEnv(model, action_low=[-0.3, -0.3], action_high=[0.3, 0.3], task=GoalReaching())
    planner = BoxCEMPlanner(env, num_candidates=64, optim_steps=2, top_k=8)
    module = com_model_module(model)
    sequence = TensorDictSequential(planner, module)
    state = env.initial_state(torch.randn(4, 5), episode=torch.arange(4))
    out = sequence(state.clone())
    with torch.no_grad():
        expected = model.predict(out["com_state"], out["action"])
    torch.testing.assert_close(out["next", "com_state"], expected)
    if isinstance(model, CoMEnsembleModel):
        assert module.out_keys == [("next", "com_state"), ("next", "com_state_std"), ("next", "com_state_members")]
        members = out["next", "com_state_members"]
        assert members.shape == (4, 3, 5)
        torch.testing.assert_close(out["next", "com_state_std"][:, [0, 1, 3, 4]],
                                   members[..., [0, 1, 3, 4]].std(-2, correction=0))
    else:
        assert module.out_keys == [("next", "com_state")]


def test_modules_export_with_torch_export(low_level):
    """torch.export of the ensemble's module and of the low level's (called with their keys as keyword tensors): the
    exported programs give the modules' outputs on new inputs. (A dynamic batch dimension is refused by torch.export
    for keyword inputs of a TensorDictModule here; ``hierloco.exporting`` exports the wrapped modules with one.)"""
    torch.manual_seed(0)
    com = com_model_module(CoMEnsembleModel(action_dim=2, hidden=16, members=3))
    state, action = torch.randn(6, 5), torch.rand(6, 2)
    program = torch.export.export(com, args=(), kwargs={"com_state": state, "action": action}, strict=False)
    state, action = torch.randn(6, 5), torch.rand(6, 2)
    exported, reference = program.module()(com_state=state, action=action), com(com_state=state, action=action)
    assert len(exported) == 3
    for x, y in zip(exported, reference):
        torch.testing.assert_close(x, y)
    low = low_level.as_module()
    program = torch.export.export(low, args=(), kwargs={"latent": torch.zeros(5, 2), "phase": torch.rand(5, 1)},
                                  strict=False)
    z, phase = torch.rand(5, 2), torch.rand(5, 1)
    torch.testing.assert_close(program.module()(latent=z, phase=phase), low(latent=z, phase=phase))

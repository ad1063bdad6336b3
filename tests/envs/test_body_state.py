"""What the trunk feels of the ground (``body_state``: roll, pitch, height above the ground; ``docs/terrain.md``): the
batched simulator measures it as falls are judged, the latent-action env reports it after every action, dynamics
data records it, and a world model whose CoM model reads it holds it over the horizon."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hierloco.components.dynamics_data import TransitionData
from hierloco.envs.batched_sim import BatchedSimulator
from hierloco.envs.frames import quat_to_roll_pitch_yaw
from hierloco.envs.robots import get_robot
from hierloco.envs.tasks import GoalReaching
from hierloco.envs.world_model import CoMWorldModelEnv


@pytest.mark.parametrize("terrain", [None, {"name": "rough", "difficulty": 1.0, "seed": 2}])
def test_the_body_state_is_roll_pitch_and_the_height_above_the_ground_below(terrain):
    robot = get_robot("a1")
    sim = BatchedSimulator(robot, 3, seed=0, terrain=terrain)
    sim.run(np.tile(np.asarray(robot.standing_pose), (3, 50, 1)))
    body = sim.body_state
    qpos = sim.qpos
    assert body.shape == (3, 3)
    np.testing.assert_allclose(body[:, :2], quat_to_roll_pitch_yaw(qpos[:, 3:7])[:, :2])
    ground = 0.0 if terrain is None else sim.terrain.ground_below(qpos[:, 0], qpos[:, 1], sim._ground_reach)
    np.testing.assert_allclose(body[:, 2], qpos[:, 2] - ground)
    # standing: nearly level, at about the robot's standing height above the ground
    assert np.all(np.abs(body[:, :2]) < 0.15) and np.all(np.abs(body[:, 2] - robot.standing_height) < 0.06), body
    if terrain is not None:
        assert np.any(ground > 0.0)  # the bumps under the robots are not the floor


def test_the_latent_env_reports_the_body_state_and_dynamics_data_records_it(tmp_path):
    from hierloco.components.dynamics_data import collect_transitions
    from hierloco.components.low_level import CommandLowLevel
    from hierloco.envs.latent_env import LatentActionEnv

    env = LatentActionEnv(CommandLowLevel("a1", 4), num_robots=4, seed=0, terrain={"name": "slope", "difficulty": 0.5})
    td = env.reset()
    np.testing.assert_allclose(td["body_state"].numpy(), env.sim.body_state, atol=1e-6)
    td = env.step(td.set("action", torch.tensor([[0.3, 0.0, 0.0]]).expand(4, 3)))
    np.testing.assert_allclose(td["next", "body_state"].numpy(), env.sim.body_state, atol=1e-6)
    data = collect_transitions(env, 12, episode_length=3, seed=0)
    env.close()
    assert data.body_state.shape == (12, 3) and np.isfinite(data.body_state).all()
    data.save(tmp_path / "data.npz")
    again = TransitionData.load(tmp_path / "data.npz")
    np.testing.assert_array_equal(again.body_state, data.body_state)
    # data collected before the body state was recorded still loads, without it
    TransitionData(data.com_state, data.action, data.next_com_state, data.metadata).save(tmp_path / "old.npz")
    assert TransitionData.load(tmp_path / "old.npz").body_state is None


class Tilted(torch.nn.Module):
    """A stand-in model over ``[action (2), roll, pitch, height]``: moves by the action, slowed by the pitch."""

    def predict(self, com_state, features):
        step = features[..., :2] * (1.0 - features[..., 3:4])
        return torch.cat([com_state[..., :2] + step, com_state[..., 2:]], -1)


def test_a_world_model_holds_the_body_state_over_the_horizon_and_needs_it():
    env = CoMWorldModelEnv(Tilted(), action_low=[-1, -1], action_high=[1, 1], task=GoalReaching(),
                           context={"body_state": 3})
    assert env.measured_keys == ["com_state", "task_episode", "task_step", "body_state"]
    td = env.initial_state(torch.zeros(2, 5))
    td["body_state"] = torch.tensor([[0.0, 0.0, 0.27], [0.0, 0.5, 0.27]])
    for _ in range(3):
        td = env.step(td.set("action", torch.tensor([[0.2, 0.0], [0.2, 0.0]])))["next"]
    np.testing.assert_allclose(td["body_state"], [[0.0, 0.0, 0.27], [0.0, 0.5, 0.27]])
    np.testing.assert_allclose(td["com_state"][:, 0], [0.6, 0.3], atol=1e-6)  # the pitched robot at half speed
    # the imagined return on tensors (the compiled planners' path) agrees with stepping the env
    actions = torch.full((2, 1, 3, 2), 0.2)
    actions[..., 1] = 0.0
    start = env.initial_state(torch.zeros(2, 5))
    body = torch.tensor([[0.0, 0.0, 0.27], [0.0, 0.5, 0.27]])
    total = env.imagined_return(start["com_state"], start["task_episode"], start["task_step"], actions, body)
    stepped = start.clone().set("body_state", body)
    rewards = torch.zeros(2)
    for h in range(3):
        stepped = env.step(stepped.set("action", actions[:, 0, h]))
        rewards += stepped["next", "reward"].squeeze(-1)
        stepped = stepped["next"]
    np.testing.assert_allclose(total[:, 0], rewards, atol=1e-5)
    with pytest.raises(KeyError, match="also reads body_state"):
        env.step(env.initial_state(torch.zeros(2, 5)).set("action", torch.zeros(2, 2)))
    with pytest.raises(ValueError, match="context"):
        CoMWorldModelEnv(Tilted(), action_low=[-1, -1], action_high=[1, 1], context={"com_state": 5})


def test_a_checkpoint_that_names_another_context_is_refused_in_one_line():
    """A run directory is data: a model whose metadata asks the world model for a state the env does not report is
    an ArtifactError, not a world model that fails later."""
    from hierloco.components.com_model import CoMDynamicsModel, TrainedCoMModel
    from hierloco.components.low_level import CommandLowLevel
    from hierloco.io import ArtifactError
    from hierloco.trained import make_world_model

    low = CommandLowLevel("a1", 1)
    trained = TrainedCoMModel(CoMDynamicsModel(action_dim=6, hidden=8), {"context": {"body_state": 3}})
    assert make_world_model(trained, low).measured_keys[-1] == "body_state"
    for context in ({"body_state": 4}, {"secret": 3}):
        with pytest.raises(ArtifactError, match="not a state the latent-action env reports"):
            make_world_model(TrainedCoMModel(CoMDynamicsModel(action_dim=6, hidden=8), {"context": context}), low)

"""The SAC parts: actions inside the box, learning a known optimum, gradients to the right parameters, checkpoints."""

import pytest
import torch
from tensordict import TensorDict

from hierloco.components.sac import SACAgent
from hierloco.io import ArtifactError

LOW, HIGH = [-1.0, -1.0], [1.0, 1.0]


def _bandit_batch(agent, size, target, generator):
    """One-step episodes: observation o, action a, reward -||a - target(o)||, always done."""
    obs = torch.rand(size, 7, generator=generator) * 2 - 1
    action = torch.rand(size, 2, generator=generator) * 2 - 1
    best = target(obs)
    reward = -(action - best).norm(dim=-1, keepdim=True)
    done = torch.ones(size, 1, dtype=torch.bool)
    return TensorDict({"goal_observation": obs, "action": action,
                       "next": {"goal_observation": obs, "reward": reward, "done": done, "terminated": done}},
                      batch_size=[size])


def test_actions_stay_in_the_box():
    agent = SACAgent.build(7, [-0.3, 0.0], [0.5, 2.0], hidden=32)
    td = agent.actor(TensorDict({"goal_observation": 10 * torch.randn(512, 7)}, batch_size=[512]))
    assert torch.all(td["action"] >= torch.tensor([-0.3, 0.0])) and torch.all(td["action"] <= torch.tensor([0.5, 2.0]))


def test_learns_a_goal_conditioned_optimum():
    """A contextual bandit whose best action is half the first two observation entries: the mean action of the
    trained actor lands within 0.15 of it (an untrained actor is about 0.5 away)."""
    torch.manual_seed(0)
    agent = SACAgent.build(7, LOW, HIGH, hidden=64, lr=1e-3, seed=0)
    target = lambda obs: 0.5 * obs[:, :2]  # noqa: E731
    generator = torch.Generator().manual_seed(0)
    for _ in range(600):
        agent.update(_bandit_batch(agent, 256, target, generator))
    test = torch.rand(200, 7, generator=generator) * 2 - 1
    from tensordict.nn import InteractionType, set_interaction_type

    with set_interaction_type(InteractionType.DETERMINISTIC):
        action = agent.actor(TensorDict({"goal_observation": test}, batch_size=[200]))["action"]
    error = (action - target(test)).norm(dim=-1).mean()
    assert error < 0.15, float(error)


def test_each_loss_term_trains_its_own_parameters():
    agent = SACAgent.build(7, LOW, HIGH, hidden=16)
    batch = _bandit_batch(agent, 32, lambda o: o[:, :2] * 0, torch.Generator().manual_seed(1))
    out = agent.loss(batch)
    actor_params = list(agent.loss.actor_network_params.values(True, True))
    out["loss_qvalue"].backward(retain_graph=True)
    assert all(p.grad is None or p.grad.abs().sum() == 0 for p in actor_params), "the Q loss must not move the actor"
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in agent.loss.qvalue_network_params.values(True, True))


def test_checkpoint_round_trip(tmp_path):
    agent = SACAgent.build(7, LOW, HIGH, hidden=16, seed=3)
    agent.update(_bandit_batch(agent, 32, lambda o: o[:, :2], torch.Generator().manual_seed(2)))
    path = tmp_path / "sac.pt"
    agent.metadata = {"frames": 32}
    agent.save(path)
    loaded = SACAgent.load(path)
    obs = TensorDict({"goal_observation": torch.randn(8, 7)}, batch_size=[8])
    from tensordict.nn import InteractionType, set_interaction_type

    with set_interaction_type(InteractionType.DETERMINISTIC):
        torch.testing.assert_close(loaded.actor(obs.clone())["action"], agent.actor(obs.clone())["action"])
    assert loaded.metadata == {"frames": 32}
    path.write_bytes(path.read_bytes()[:300])
    with pytest.raises(ArtifactError, match="corrupted"):
        SACAgent.load(path)


def test_bad_box_is_refused():
    with pytest.raises(ValueError, match="action box"):
        SACAgent.build(7, [1.0], [0.0])

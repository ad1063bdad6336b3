"""The SAC parts: actions inside the box, learning a known optimum, gradients to the right parameters, seeding,
checkpoints that resume training exactly, the batched training loop (resume, refusal of another run's checkpoint)."""

import pytest
import torch
from tensordict import TensorDict

from hierloco.components.sac import (
    PAPER_HIDDEN,
    PAPER_LR,
    SACAgent,
    torch_threads,
    train_sac,
)
from hierloco.io import ArtifactError

LOW, HIGH = [-1.0, -1.0], [1.0, 1.0]


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Small networks on shared cores: one torch thread (see torch_threads)."""
    with torch_threads(1):
        yield


def _bandit_batch(size, target, generator):
    """One-step episodes: observation o, action a, reward -||a - target(o)||, always done."""
    obs = torch.rand(size, 7, generator=generator) * 2 - 1
    action = torch.rand(size, 2, generator=generator) * 2 - 1
    best = target(obs)
    reward = -(action - best).norm(dim=-1, keepdim=True)
    done = torch.ones(size, 1, dtype=torch.bool)
    return TensorDict({"goal_observation": obs, "action": action,
                       "next": {"goal_observation": obs, "reward": reward, "done": done, "terminated": done}},
                      batch_size=[size])


def _parameters(agent):
    return torch.cat([p.detach().flatten() for p in agent.loss.parameters()])


def test_paper_networks_by_default():
    agent = SACAgent.build(7, LOW, HIGH)
    linears = [m for m in agent.actor.modules() if isinstance(m, torch.nn.Linear)]
    assert [m.out_features for m in linears[:-1]] == [PAPER_HIDDEN, PAPER_HIDDEN] == [512, 512]
    assert agent.optimizer.param_groups[0]["lr"] == PAPER_LR == 1e-3


def test_actions_stay_in_the_box():
    agent = SACAgent.build(7, [-0.3, 0.0], [0.5, 2.0], hidden=32)
    td = agent.actor(TensorDict({"goal_observation": 10 * torch.randn(512, 7)}, batch_size=[512]))
    assert torch.all(td["action"] >= torch.tensor([-0.3, 0.0])) and torch.all(td["action"] <= torch.tensor([0.5, 2.0]))
    mode = agent.act(10 * torch.randn(64, 7))
    assert torch.all(mode >= torch.tensor([-0.3, 0.0])) and torch.all(mode <= torch.tensor([0.5, 2.0]))


def test_learns_a_goal_conditioned_optimum():
    """A contextual bandit whose best action is half the first two observation entries: the mean action of the
    trained actor lands within 0.15 of it (the untrained actor is about 0.4 away)."""
    torch.manual_seed(0)
    agent = SACAgent.build(7, LOW, HIGH, hidden=64, lr=1e-3, seed=0)
    untrained = SACAgent.build(7, LOW, HIGH, hidden=64, lr=1e-3, seed=0)
    target = lambda obs: 0.5 * obs[:, :2]  # noqa: E731
    generator = torch.Generator().manual_seed(0)
    for _ in range(600):
        agent.update(_bandit_batch(256, target, generator))
    test = torch.rand(200, 7, generator=generator) * 2 - 1
    before = (untrained.act(test) - target(test)).norm(dim=-1).mean()
    error = (agent.act(test) - target(test)).norm(dim=-1).mean()
    assert before > 0.3 and error < 0.15, (float(before), float(error))


def test_each_loss_term_trains_its_own_parameters():
    agent = SACAgent.build(7, LOW, HIGH, hidden=16)
    batch = _bandit_batch(32, lambda o: o[:, :2] * 0, torch.Generator().manual_seed(1))
    out = agent.loss(batch)
    actor_params = list(agent.loss.actor_network_params.values(True, True))
    out["loss_qvalue"].backward(retain_graph=True)
    assert all(p.grad is None or p.grad.abs().sum() == 0 for p in actor_params), "the Q loss must not move the actor"
    q_params = agent.loss.qvalue_network_params.values(True, True)
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in q_params)


def test_same_seed_same_agent_and_updates():
    """Every network (both Q nets and their targets included) comes from the seed, and so do the updates."""
    batches = [_bandit_batch(64, lambda o: o[:, :2], torch.Generator().manual_seed(i)) for i in range(5)]
    runs = []
    for seed in (3, 3, 4):
        agent = SACAgent.build(7, LOW, HIGH, hidden=16, seed=seed)
        start = _parameters(agent)
        torch.manual_seed(0)
        for batch in batches:
            agent.update(batch.clone())
        runs.append((start, _parameters(agent)))
    assert torch.equal(runs[0][0], runs[1][0]) and torch.equal(runs[0][1], runs[1][1])
    assert not torch.equal(runs[0][0], runs[2][0])


def test_checkpoint_resumes_training_exactly(tmp_path):
    """A saved and loaded agent carries its metadata and optimiser state: its next updates equal the original's."""
    agent = SACAgent.build(7, LOW, HIGH, hidden=16, seed=3)
    generator = torch.Generator().manual_seed(2)
    for _ in range(3):
        agent.update(_bandit_batch(32, lambda o: o[:, :2], generator))
    agent.metadata = {"frames": 96}
    path = tmp_path / "sac.pt"
    agent.save(path)
    loaded = SACAgent.load(path)
    assert isinstance(loaded, SACAgent) and loaded.metadata == {"frames": 96} and loaded.updates == 3
    torch.testing.assert_close(loaded.act(torch.ones(4, 7)), agent.act(torch.ones(4, 7)))
    batches = [_bandit_batch(32, lambda o: o[:, :2], generator) for _ in range(3)]
    for copy in (agent, loaded):
        torch.manual_seed(7)
        for batch in batches:
            copy.update(batch.clone())
    assert torch.equal(_parameters(agent), _parameters(loaded))
    path.write_bytes(path.read_bytes()[:300])
    with pytest.raises(ArtifactError, match="corrupted"):
        SACAgent.load(path)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="action box"):
        SACAgent.build(7, [1.0], [0.0])
    with pytest.raises(ValueError, match="gamma"):
        SACAgent.build(7, LOW, HIGH, gamma=1.5)


def test_torch_threads_is_restored():
    before = torch.get_num_threads()
    with torch_threads(1):
        assert torch.get_num_threads() == 1
    assert torch.get_num_threads() == before


class _Bandit:
    """A batched one-step TorchRL env for the training loop: reward -||a - 0.5 o[:2]||."""

    @staticmethod
    def make(batch=8, seed=0):
        from torchrl.data import Bounded, Categorical, Composite, Unbounded
        from torchrl.envs import EnvBase

        class Env(EnvBase):
            def __init__(self):
                super().__init__(batch_size=torch.Size([batch]))
                self.observation_spec = Composite(goal_observation=Unbounded((batch, 7)), shape=(batch,))
                self.action_spec = Bounded(-torch.ones(batch, 2), torch.ones(batch, 2), (batch, 2))
                self.reward_spec = Unbounded((batch, 1))
                flag = Categorical(2, (batch, 1), dtype=torch.bool)
                self.done_spec = Composite(done=flag, terminated=flag.clone(), truncated=flag.clone(),
                                           shape=(batch,))
                self.generator = torch.Generator().manual_seed(seed)

            def _observe(self):
                self.obs = torch.rand(batch, 7, generator=self.generator) * 2 - 1
                return self.obs

            def _reset(self, td=None, **kwargs):
                done = torch.zeros(batch, 1, dtype=torch.bool)
                return TensorDict({"goal_observation": self._observe(), "done": done, "terminated": done.clone(),
                                   "truncated": done.clone()}, batch_size=self.batch_size)

            def _step(self, td):
                reward = -(td["action"] - 0.5 * self.obs[:, :2]).norm(dim=-1, keepdim=True)
                done = torch.ones(batch, 1, dtype=torch.bool)
                return TensorDict({"goal_observation": self._observe(), "reward": reward, "done": done,
                                   "terminated": done.clone(), "truncated": torch.zeros_like(done)},
                                  batch_size=self.batch_size)

            def _set_seed(self, seed):
                self.generator = torch.Generator().manual_seed(int(seed or 0))

        return Env()


def test_train_sac_learns_resumes_and_refuses_other_settings(tmp_path):
    """The batched loop raises the bandit's reward; killed half way (simulated by a shorter run), it resumes from
    its checkpoint to the same frame count; a checkpoint of other settings is refused."""
    path = tmp_path / "training.pt"
    kwargs = dict(init_random_frames=256, updates_per_frame=0.5, batch_size=128, buffer_size=4096, log_every=256,
                  checkpoint_path=path, checkpoint_every=512, progress=False, settings={"run": 1})
    agent = SACAgent.build(7, LOW, HIGH, hidden=64, seed=0)
    first = train_sac(_Bandit.make(), agent, total_frames=1024, **kwargs)
    assert path.exists() and first["frames"] == 1024 and len(first["learning_curve"]) == 4
    resumed_agent = SACAgent.build(7, LOW, HIGH, hidden=64, seed=0)
    report = train_sac(_Bandit.make(), resumed_agent, total_frames=3072, **kwargs)
    curve = report["learning_curve"]
    assert report["frames"] == 3072 and [p["frames"] for p in curve] == list(range(256, 3073, 256))
    assert resumed_agent.updates == ((3072 - 256) // 8 + 1) * 4  # 4 updates per step of 8 frames from frame 256
    assert curve[-1]["reward"] > curve[0]["reward"] + 0.2, [round(p["reward"], 3) for p in curve]
    with pytest.raises(ValueError, match="other settings"):
        train_sac(_Bandit.make(), SACAgent.build(7, LOW, HIGH, hidden=64), total_frames=4096,
                  **{**kwargs, "settings": {"run": 2}})


@pytest.mark.slow
def test_compiled_update_matches_eager():
    """torch.compile of the loss gives the eager loss terms (same weights, same batch, same random draws)."""
    import torch._inductor.config as inductor_config

    batch = _bandit_batch(64, lambda o: o[:, :2], torch.Generator().manual_seed(0))
    eager = SACAgent.build(7, LOW, HIGH, hidden=32, seed=1)
    compiled = SACAgent.build(7, LOW, HIGH, hidden=32, seed=1, compile_update=True)
    with inductor_config.patch(fallback_random=True):
        for _ in range(3):
            results = []
            for agent in (eager, compiled):
                torch.manual_seed(5)
                results.append(agent.update(batch.clone()))
            for key in results[0]:
                assert results[0][key] == pytest.approx(results[1][key], rel=1e-4, abs=1e-5), key
    torch.testing.assert_close(_parameters(eager), _parameters(compiled), rtol=1e-4, atol=1e-5)

"""SAC parts: actor, Q networks, TorchRL's ``SACLoss`` and a fast training update (Li et al., RA-L 2021, baselines).

The actor maps an observation (a goal observation, :class:`hierloco.envs.transforms.GoalObservation`, for the
SAC high level over z; the proprioceptive observation of :mod:`hierloco.envs.velocity_command_env` for SAC-SAC's
low level) to an action in a box through a tanh-squashed Gaussian; two Q networks score (observation, action). The
loss is TorchRL's :class:`~torchrl.objectives.SACLoss` (v2: two Q nets, a learned temperature, soft-updated target
Q networks).

The paper's networks and optimiser are the defaults: 2 hidden layers of 512 ReLU units, Adam with learning rate
1e-3 ("All neural network policies and dynamics models have 2 hidden layers with 512 nodes", batch 512:
``PAPER_BATCH_SIZE``). One update is one ``SACLoss`` forward and backward, one fused Adam step and one soft target
update; with ``compile_update=True`` the loss forward and backward are compiled with :func:`torch.compile`
(it removes most of the Python overhead of small networks, at a one-off compile cost of about a minute on two
cores; ``benchmarks/bench_sac.py`` measures both), with CUDA graphs on a GPU (``mode="reduce-overhead"``,
:func:`hierloco.devices.compile_mode`; a mode name chooses another). The agent, its loss and the replay buffer live
on ``device``; the env stays on the CPU and each env step crosses once each way (``docs/gpu.md``). Train with one
torch thread (:func:`torch_threads`, the default of :func:`train_sac`) when cores are shared: small updates run many
times faster than with two.

Example:
    >>> import torch
    >>> from tensordict import TensorDict
    >>> agent = SACAgent.build(observation_dim=7, action_low=[-1.0, -1.0], action_high=[1.0, 1.0], hidden=32)
    >>> td = agent.actor(TensorDict({"goal_observation": torch.zeros(4, 7)}, batch_size=[4]))
    >>> td["action"].shape
    torch.Size([4, 2])
    >>> agent.act(torch.zeros(4, 7)).shape  # the deterministic (mode) action, B x A
    torch.Size([4, 2])
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Mapping, Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import InteractionType, NormalParamExtractor, TensorDictModule, set_interaction_type
from torch import nn
from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
from torchrl.envs import EnvBase
from tqdm.auto import tqdm
from torchrl.modules import MLP, ProbabilisticActor, TanhNormal, ValueOperator
from torchrl.objectives import SACLoss, SoftUpdate

from hierloco.devices import compile_mode, is_cuda
from hierloco.io import load_checkpoint, save_checkpoint

CHECKPOINT_KIND, CHECKPOINT_FORMAT = "sac_agent", 2
TRAINING_KIND, TRAINING_FORMAT = "sac_training", 1

PAPER_HIDDEN = 512  # units in each of the 2 hidden layers (Li et al., RA-L 2021)
PAPER_LR = 1e-3  # Adam learning rate
PAPER_BATCH_SIZE = 512  # transitions per update

LOSS_TERMS = ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy")


def _loss_terms(loss: SACLoss) -> Callable[[TensorDictBase], tuple[torch.Tensor, dict]]:
    """``batch -> (total loss, {term: tensor})`` for ``loss``: what is compiled when the update is compiled."""

    def terms(batch: TensorDictBase):
        out = loss(batch)
        total = out["loss_actor"] + out["loss_qvalue"] + out["loss_alpha"]
        return total, {key: out[key].detach() for key in LOSS_TERMS}

    return terms


@dataclass
class SACAgent:
    """The actor, the Q networks, the SAC loss, its optimiser, the target-network updater and a metadata dict.

    Build one with :meth:`build`; :meth:`update` does one gradient step on a replay batch; :meth:`save` and
    :meth:`load` write and read a checkpoint that holds everything needed to resume training (weights, target
    networks, temperature, optimiser state, update count, metadata).
    """

    actor: ProbabilisticActor
    qvalue: ValueOperator
    loss: SACLoss
    optimizer: torch.optim.Optimizer
    target_updater: SoftUpdate
    config: dict
    metadata: dict = field(default_factory=dict)
    updates: int = 0
    compile_update: bool | str = False
    _terms: Callable | None = field(default=None, repr=False)

    def __post_init__(self):
        if self._terms is None:
            self._terms = _loss_terms(self.loss)

    @classmethod
    def build(cls, observation_dim: int, action_low: Sequence[float], action_high: Sequence[float], *,
              hidden: int = PAPER_HIDDEN, num_layers: int = 2, lr: float = PAPER_LR, gamma: float = 0.95,
              tau: float = 0.005, alpha_init: float = 1.0, observation_key: str = "goal_observation",
              compile_update: bool | str = False, seed: int = 0, device="cpu") -> "SACAgent":
        """An agent for observations of size ``observation_dim`` and actions in ``[action_low, action_high]``.

        Args:
            observation_dim: size of the (flat) observation at ``observation_key``.
            action_low, action_high: the action box (``A`` each).
            hidden, num_layers: ReLU MLPs of ``num_layers`` hidden layers of ``hidden`` units (actor and Q nets).
            lr: Adam learning rate of the actor, the Q networks and the temperature.
            gamma: discount per step; tau: soft target-update rate.
            alpha_init: initial entropy temperature (then learned).
            compile_update: compile the loss forward and backward with :func:`torch.compile` (at the first update;
                dynamo recompiles for each compiled agent of a process and falls back to eager after 8): ``True``
                in the mode for ``device`` (CUDA graphs on a GPU, :func:`hierloco.devices.compile_mode`), or a
                ``torch.compile`` mode name.
            seed: seeds the network initialisation (the global RNG is left as it was): the networks are initialised
                on the CPU and then moved, so every device starts from the same weights.
            device: where the networks, the loss and the optimiser live (``cpu``, ``cuda``).
        """
        config = {"observation_dim": int(observation_dim), "action_low": [float(v) for v in action_low],
                  "action_high": [float(v) for v in action_high], "hidden": int(hidden), "num_layers": int(num_layers),
                  "lr": float(lr), "gamma": float(gamma), "tau": float(tau), "alpha_init": float(alpha_init),
                  "observation_key": observation_key, "seed": int(seed)}
        low = torch.as_tensor(config["action_low"], device="cpu")
        high = torch.as_tensor(config["action_high"], device="cpu")
        if low.ndim != 1 or low.numel() == 0 or low.shape != high.shape or not torch.all(low < high):
            raise ValueError(f"bad action box: low {action_low}, high {action_high}")
        if config["observation_dim"] < 1 or config["hidden"] < 1 or config["num_layers"] < 1:
            raise ValueError(f"observation_dim, hidden and num_layers must be positive, got {observation_dim}, "
                             f"{hidden}, {num_layers}")
        if not (config["lr"] > 0 and 0 < config["gamma"] < 1 and 0 < config["tau"] <= 1 and config["alpha_init"] > 0):
            raise ValueError(f"need lr > 0, 0 < gamma < 1, 0 < tau <= 1, alpha_init > 0; got lr={lr}, gamma={gamma}, "
                             f"tau={tau}, alpha_init={alpha_init}")
        dim = len(low)
        cells = [config["hidden"]] * config["num_layers"]
        box_low, box_high = low.to(device), high.to(device)  # the squashing box, where the actions are made
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            net = nn.Sequential(MLP(in_features=observation_dim, out_features=2 * dim, num_cells=cells,
                                    activation_class=nn.ReLU), NormalParamExtractor())
            actor = ProbabilisticActor(
                TensorDictModule(net, in_keys=[observation_key], out_keys=["loc", "scale"]),
                spec=Bounded(box_low, box_high, (dim,), device=device), in_keys=["loc", "scale"],
                distribution_class=TanhNormal, distribution_kwargs={"low": box_low, "high": box_high},
                return_log_prob=False)
            qvalue = ValueOperator(MLP(in_features=observation_dim + dim, out_features=1, num_cells=cells,
                                       activation_class=nn.ReLU), in_keys=[observation_key, "action"])
            # SACLoss initialises the second Q network (and the target copies) from the global RNG: seed it too.
            # Eagerly, a loop over the two Q nets is faster on CPU than vmap; compiled, vmap is (and the loop
            # recompiles at every call): benchmarks/bench_sac.py
            loss = SACLoss(actor, qvalue, num_qvalue_nets=2, loss_function="l2", alpha_init=config["alpha_init"],
                           deactivate_vmap=not compile_update)
        loss.make_value_estimator(gamma=config["gamma"])
        loss.to(device)  # the actor follows (its parameters are the loss's); the Q networks are the loss's own
        qvalue.to(device)
        # fused: one kernel for every parameter instead of a Python loop over them
        optimizer = torch.optim.Adam(loss.parameters(), lr=config["lr"], fused=True)
        terms = _loss_terms(loss)
        if compile_update:
            mode = compile_mode(device) if compile_update is True else str(compile_update)
            terms = torch.compile(terms, mode=mode)
        return cls(actor, qvalue, loss, optimizer, SoftUpdate(loss, tau=config["tau"]), config,
                   compile_update=compile_update, _terms=terms)

    @property
    def observation_key(self) -> str:
        return self.config["observation_key"]

    @property
    def device(self) -> torch.device:
        """Where the networks live."""
        return next(self.loss.parameters()).device

    def update(self, batch: TensorDictBase, *, as_floats: bool = True) -> dict:
        """One gradient step on a replay batch (``M`` transitions with the observation, ``action`` and the
        ``("next", ...)`` observation, ``reward``, ``done``, ``terminated``, on the agent's device); returns the
        detached loss terms, the temperature ``alpha`` and the policy ``entropy`` as floats (``as_floats=False``:
        as tensors on the device, so the update waits for nothing)."""
        total, terms = self._terms(batch)
        self.optimizer.zero_grad(set_to_none=True)
        total.backward()
        self.optimizer.step()
        self.target_updater.step()
        self.updates += 1
        if as_floats:
            return {key: float(value) for key, value in terms.items()}
        return {key: value.clone() for key, value in terms.items()}  # a graphed update reuses its output memory

    @torch.no_grad()
    def act(self, observation: torch.Tensor, deterministic: bool = True) -> torch.Tensor:
        """``B x D`` observations -> ``B x A`` actions (on the observations' device): the squashed mean
        (``deterministic``) or a sample."""
        mode = InteractionType.DETERMINISTIC if deterministic else InteractionType.RANDOM
        td = TensorDict({self.observation_key: observation.to(self.device)}, batch_size=observation.shape[:-1])
        with set_interaction_type(mode):
            return self.actor(td)["action"].to(observation.device)

    def actor_on(self, device) -> ProbabilisticActor:
        """The actor on ``device``: itself when it is there, else a copy moved there (e.g. to act on the CPU with an
        agent trained on a GPU)."""
        if torch.device(device) == self.device:
            return self.actor
        import copy

        return copy.deepcopy(self.actor).to(device)

    def state(self) -> dict:
        """Everything :meth:`from_state` needs (config, networks with targets and temperature, optimiser state,
        update count, metadata), as plain tensors and Python values (loadable with ``weights_only``)."""
        return {"config": self.config, "loss_state": self.loss.state_dict(),
                "optimizer_state": self.optimizer.state_dict(), "updates": self.updates, "metadata": self.metadata}

    @classmethod
    def from_state(cls, state: dict, *, compile_update: bool | str = False, device="cpu") -> "SACAgent":
        """The agent :meth:`state` describes, on ``device``, ready to act or to resume training."""
        agent = cls.build(**state["config"], compile_update=compile_update, device=device)
        agent.load_state(state)
        return agent

    def load_state(self, state: dict) -> None:
        """Takes the weights, targets, temperature, optimiser state, update count and metadata of :meth:`state`
        (of an agent with the same config) in place."""
        if state["config"] != self.config:
            changed = sorted(k for k in self.config if state["config"].get(k) != self.config[k])
            raise ValueError(f"the saved agent has another config ({', '.join(changed)})")
        self.loss.load_state_dict(state["loss_state"])
        self.optimizer.load_state_dict(state["optimizer_state"])
        self.updates = int(state["updates"])
        self.metadata = dict(state["metadata"])

    def save(self, path: str | os.PathLike) -> None:
        """Writes a checkpoint (:meth:`state`) to ``path`` atomically."""
        save_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, self.state())

    @classmethod
    def load(cls, path: str | os.PathLike, *, compile_update: bool | str = False, map_location="cpu",
             device="cpu") -> "SACAgent":
        """The agent saved at ``path`` (on any device: read through ``map_location``), on ``device``, ready to act
        or to resume training; its ``metadata`` is the saved one."""
        return cls.from_state(load_checkpoint(path, CHECKPOINT_KIND, CHECKPOINT_FORMAT, map_location),
                              compile_update=compile_update, device=device)


@contextmanager
def torch_threads(num_threads: int | None) -> Iterator[None]:
    """Runs the block with ``num_threads`` torch intra-op threads (``None``: unchanged), then restores them.

    On a machine whose cores are shared (with the simulation's threads or other processes), small networks update
    several times faster on one thread than on two: a parallel op waits for its slowest thread
    (``benchmarks/bench_sac.py`` measures it).
    """
    if num_threads is None:
        yield
        return
    previous = torch.get_num_threads()
    torch.set_num_threads(int(num_threads))
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _reward_diagnostics(next_td: TensorDictBase) -> dict:
    return {"reward": float(next_td["reward"].mean()), "done": float(next_td["done"].float().mean())}


def train_sac(env: EnvBase, agent: SACAgent, *, total_frames: int, init_random_frames: int = 1000,
              updates_per_frame: float = 1.0, batch_size: int = PAPER_BATCH_SIZE, buffer_size: int = 100_000,
              log_every: int = 1000, diagnostics: Callable[[TensorDictBase], Mapping[str, float]] | None = None,
              checkpoint_path: str | os.PathLike | None = None, checkpoint_every: int = 10_000,
              settings: Mapping | None = None, torch_threads_during: int | None = 1, seed: int = 0,
              progress: bool = False, logger=None, tag: str = "sac") -> dict:
    """Off-policy SAC on a batched env: collect one env step (``B`` frames), store it, update, repeat.

    ``B`` is the env's batch size (robots stepped together: :class:`hierloco.envs.latent_env.LatentActionEnv`
    with many robots for a high level, :class:`hierloco.envs.velocity_command_env.VelocityCommandEnv` for SAC-SAC's
    low level); done robots are reset one by one (``env.step_and_maybe_reset``). The env runs on the CPU and the
    agent and the replay buffer on the agent's device: each step's observations cross to the agent once, its
    actions back once, its transition into the buffer once. The first ``init_random_frames``
    frames take uniformly random actions; after that the actor explores and ``updates_per_frame`` updates per
    collected frame follow (fractions accumulate across steps), each on ``batch_size`` transitions sampled uniformly
    from the last ``buffer_size``. ``agent`` is trained in place.

    Every ``checkpoint_every`` frames and at the end the whole training state (agent with optimiser, replay buffer,
    learning curve, RNG) is written atomically to ``checkpoint_path``; when that file exists at the start, training
    resumes from it (its ``settings`` must equal ``settings``) instead of starting over; the resumed run is not
    bit-identical to an uninterrupted one (the env restarts its episodes).

    Args:
        env: a TorchRL env with batch size ``[B]`` whose observation is at ``agent.observation_key``.
        agent: the :class:`SACAgent`.
        total_frames: frames (robot steps) to collect, summed over robots.
        diagnostics: ``next tensordict -> {name: float}`` averaged into the learning curve (default: the mean
            ``reward`` and the fraction of ``done`` robots).
        settings: what identifies this training run (checked against a checkpoint on resume).
        torch_threads_during: torch threads while training (``None``: leave as is).
        seed: seeds the exploration (torch's global RNG) and, on resume, the env.
        logger: anything with ``log_metrics(dict, step=)``; metrics are ``train/<tag>/<name>``.

    Returns:
        ``frames``, ``updates``, ``train_seconds`` (wall-clock over all runs), ``seconds`` (this run's time in
        ``collection`` and ``update``; ``before_resume``: the earlier runs' time, 0 for a fresh start) and
        ``learning_curve``: every ``log_every`` frames, the ``frames``,
        ``seconds``, ``updates``, the averaged diagnostics and the last loss terms.
    """
    for name, value in (("total_frames", total_frames), ("batch_size", batch_size), ("buffer_size", buffer_size),
                        ("log_every", log_every), ("checkpoint_every", checkpoint_every)):
        if not int(value) > 0:
            raise ValueError(f"{name} must be positive, got {value}")
    if init_random_frames < 0 or updates_per_frame < 0:
        raise ValueError(f"init_random_frames and updates_per_frame must be >= 0, got {init_random_frames}, "
                         f"{updates_per_frame}")
    if len(env.batch_size) != 1:
        raise ValueError(f"the env must have a batch size [B], got {list(env.batch_size)}")
    diagnostics = diagnostics or _reward_diagnostics
    settings = dict(settings or {})
    key = agent.observation_key
    transition_keys = (key, "action", ("next", key), ("next", "reward"), ("next", "done"), ("next", "terminated"))
    device = agent.device
    env_device = env.device if env.device is not None else torch.device("cpu")
    moves = device != env_device  # the agent acts and learns elsewhere than the env steps
    storage = LazyTensorStorage(int(buffer_size), device=device) if moves else LazyTensorStorage(int(buffer_size))
    buffer = ReplayBuffer(storage=storage, batch_size=int(batch_size))
    frames, curve, elapsed, owed = 0, [], 0.0, 0.0
    torch.manual_seed(seed)
    if checkpoint_path is not None and Path(checkpoint_path).exists():
        state = load_checkpoint(checkpoint_path, TRAINING_KIND, TRAINING_FORMAT, map_location=device)
        if state["settings"] != settings:
            changed = sorted(k for k in set(settings) | set(state["settings"])
                             if state["settings"].get(k) != settings.get(k))
            raise ValueError(f"checkpoint {checkpoint_path} was made with other settings ({', '.join(changed)}); "
                             "remove it or use another checkpoint_path")
        agent.load_state(state["agent"])
        buffer.load_state_dict(state["buffer"])
        frames, curve, elapsed, owed = int(state["frames"]), list(state["curve"]), float(state["seconds"]), \
            float(state["owed"])
        torch.set_rng_state(state["torch_rng"].cpu())
        if "cuda_rng" in state and is_cuda(device):  # the actor's exploration draws on the GPU
            torch.cuda.set_rng_state(state["cuda_rng"].cpu(), device)
        env.set_seed(seed + frames)  # fresh episodes after the restart

    def save_state():
        save_checkpoint(checkpoint_path, TRAINING_KIND, TRAINING_FORMAT, {
            "settings": settings, "agent": agent.state(), "buffer": buffer.state_dict(), "frames": frames,
            "curve": curve, "seconds": time.perf_counter() - start, "owed": owed,
            "torch_rng": torch.get_rng_state(),
            **({"cuda_rng": torch.cuda.get_rng_state(device)} if is_cuda(device) else {})})

    b = env.batch_size[0]
    start = time.perf_counter() - elapsed
    seconds = {"collection": 0.0, "update": 0.0, "before_resume": elapsed}
    sums: dict[str, float] = {}
    steps, info = 0, {}
    next_log = (frames // log_every + 1) * log_every
    next_checkpoint = (frames // checkpoint_every + 1) * checkpoint_every
    bar = tqdm(total=int(total_frames), initial=min(frames, int(total_frames)), desc=tag, disable=not progress)
    with torch_threads(torch_threads_during):
        td = env.reset()
        while frames < total_frames:
            tick = time.perf_counter()
            with torch.no_grad():
                if frames < init_random_frames:
                    td.set("action", env.action_spec.rand())
                else:
                    with set_interaction_type(InteractionType.RANDOM):
                        if moves:  # the observation over, the action back: one transfer each
                            acted = agent.actor(td.select(key).to(device, non_blocking=True))
                            td.set("action", acted.get("action").to(env_device))
                        else:
                            agent.actor(td)
            transition, td = env.step_and_maybe_reset(td)
            buffer.extend(transition.select(*transition_keys))
            for name, value in diagnostics(transition["next"]).items():
                sums[name] = sums.get(name, 0.0) + float(value)
            steps += 1
            frames += b
            bar.update(b)
            seconds["collection"] += time.perf_counter() - tick
            if frames >= init_random_frames and len(buffer) >= batch_size:
                tick = time.perf_counter()
                owed += updates_per_frame * b
                while owed >= 1:
                    info = agent.update(buffer.sample(), as_floats=not moves)  # on a GPU: no wait per update
                    owed -= 1
                seconds["update"] += time.perf_counter() - tick
            if frames >= next_log or frames >= total_frames:
                point = {"frames": frames, "seconds": time.perf_counter() - start, "updates": agent.updates,
                         **{name: total / max(1, steps) for name, total in sums.items()},
                         **{k: float(info[k]) for k in ("loss_qvalue", "loss_actor", "alpha", "entropy") if k in info}}
                curve.append(point)
                sums, steps = {}, 0
                next_log += log_every
                if logger is not None:
                    logger.log_metrics({f"train/{tag}/{k}": v for k, v in point.items() if k != "frames"},
                                       step=frames)
                if "reward" in point:
                    bar.set_postfix(reward=f"{point['reward']:.3f}")
            if checkpoint_path is not None and frames >= next_checkpoint:
                save_state()
                next_checkpoint += checkpoint_every
        if checkpoint_path is not None:
            save_state()
    bar.close()
    return {"frames": frames, "updates": agent.updates, "train_seconds": time.perf_counter() - start,
            "seconds": seconds, "learning_curve": curve}

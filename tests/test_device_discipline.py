"""Device discipline: every tensor hierloco creates names its device (``docs/gpu.md``).

On a GPU machine a tensor made without a device lands on the CPU while the networks, the planner and the world model
are on CUDA, and the first operation mixing them fails (as ``device=cuda`` once did in ``Task.tracking_error``). CI
has no GPU, so these tests catch such a tensor on the CPU in two ways, on the paths a recipe takes (LAT's stages
and closed-loop evaluation with every planner, the CoM MLP and ensemble, LIB's exhaustive search, SAC's training and
evaluation), at tiny sizes:

- :class:`UndeclaredDevices` watches every tensor factory (``torch.zeros``, ``torch.as_tensor`` of an array,
  ``torch.randn``, ...) called from hierloco's or the recipes' own code and records each call that names no device,
  with its file and line; numpy-facing code must say ``device="cpu"``, the rest the device of the data it works on.
- the planners also run with ``torch.set_default_device("meta")`` while their world model is explicitly on the CPU:
  a tensor created anywhere along the way without a device (TorchRL's code included) would be a meta tensor, and
  mixing it with the CPU tensors fails.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.overrides import TorchFunctionMode
from torch.utils._device import _device_constructors

ROOT = Path(__file__).resolve().parents[1]
OURS = tuple(str(ROOT / folder) + "/" for folder in ("hierloco", "recipes"))


class UndeclaredDevices(TorchFunctionMode):
    """Records the tensor factories called from hierloco's or the recipes' code without a ``device``:
    ``found`` maps ``"path:line function"`` to the number of calls. ``torch.as_tensor`` of a tensor keeps that
    tensor's device and is not counted."""

    def __init__(self):
        super().__init__()
        self.found: dict[str, int] = {}

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if func in _device_constructors() and kwargs.get("device") is None and not (
                func in (torch.as_tensor, torch.asarray) and args and isinstance(args[0], torch.Tensor)):
            caller = sys._getframe(1)
            path = caller.f_code.co_filename
            if path.startswith(OURS):
                where = f"{Path(path).relative_to(ROOT)}:{caller.f_lineno} torch.{func.__name__}"
                self.found[where] = self.found.get(where, 0) + 1
        return func(*args, **kwargs)


def assert_none_undeclared(mode: UndeclaredDevices) -> None:
    assert not mode.found, "tensors created without a device (give device=...):\n" + "\n".join(
        f"  {where} ({count} calls)" for where, count in sorted(mode.found.items()))


def test_the_watch_catches_an_undeclared_device():
    """The watch itself: a factory without a device in hierloco's code is recorded, with a device it is not."""
    from hierloco.envs.tasks import GoalReaching

    task = GoalReaching()
    with UndeclaredDevices() as mode:
        task.start_state()                      # device="cpu" given: not recorded
        torch.zeros(3)                          # this test file is not hierloco's code: not recorded
    assert mode.found == {}
    with UndeclaredDevices() as mode:
        exec(compile("import torch\ntorch.zeros(2)\n", str(ROOT / "hierloco" / "stand_in.py"), "exec"))
    assert mode.found == {"hierloco/stand_in.py:2 torch.zeros": 1}


TASKS = {"velocity_tracking": {"steps_per_target": 1, "rounds": 1},
         "goal_reaching": {"num_goals": 2, "num_steps": 2},
         "trajectory_tracking": {"speed": 4.0, "extra_steps": 0}}
PLANNER = {"horizon": 2, "num_candidates": 16, "optim_steps": 2, "top_k": 4, "temperature": 0.05}


@pytest.fixture(scope="module")
def tiny_lat():
    """LAT's stages at tiny sizes, built under the watch: experts, gait policy, dynamics data, the CoM MLP and
    ensemble (what ``hierloco.pipeline.stages`` calls)."""
    from hierloco.components.com_model import train_com_model
    from hierloco.components.dynamics_data import collect_transitions
    from hierloco.components.expert_library import build_expert_library
    from hierloco.components.gait_policy import train_gait_policy
    from hierloco.components.low_level import LatentLowLevel
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.robots import get_robot

    robot = get_robot("a1")
    with UndeclaredDevices() as mode:
        library = build_expert_library(robot, 3, settle_time=0.5, seed=0, progress=False)
        trained = train_gait_policy(library.joint_targets, latent_dim=2, hidden=16, epochs=2, batch_size=100,
                                    device="cpu", progress=False)
        low_level = LatentLowLevel(trained, robot, device="cpu")
        env = LatentActionEnv(low_level, num_robots=4, seed=0, nthread=1)
        data = collect_transitions(env, 16, episode_length=2, seed=0, progress=False)
        env.close()
        features = low_level.action_features(data.action)
        mlp = train_com_model(data.com_state, features, data.next_com_state, hidden=16, batch_size=8, max_epochs=2,
                              device="cpu", progress=False)
        ensemble = train_com_model(data.com_state, features, data.next_com_state, model="ensemble", members=2,
                                   hidden=16, batch_size=8, max_epochs=2, device="cpu", progress=False)
    return {"robot": robot, "library": library, "low_level": low_level, "mlp": mlp, "ensemble": ensemble,
            "found": mode.found}


def test_lat_stages_name_their_devices(tiny_lat):
    mode = UndeclaredDevices()
    mode.found = tiny_lat["found"]
    assert_none_undeclared(mode)


@pytest.mark.parametrize("planner", ["random_shooting", "cem", "mppi"])
@pytest.mark.parametrize("model", ["mlp", "ensemble"])
def test_closed_loop_evaluation_names_its_devices(tiny_lat, planner, model):
    """The evaluation stage's rollout (``stages.evaluation_rollout``: world model, planner, simulated robots) on
    every task, with every box planner, on the MLP and the ensemble (risk-aware)."""
    from hierloco.envs.tasks import make_task
    from hierloco.pipeline.stages import evaluation_rollout

    params = {"setting": "normal", "seed": 0, "device": "cpu",
              "planner": {"name": planner, **PLANNER, **({"risk": "mean_std"} if model == "ensemble" else {})}}
    with UndeclaredDevices() as mode:
        for name, options in TASKS.items():
            task = make_task(name, **options)
            rollout = evaluation_rollout(tiny_lat["robot"], params, task, tiny_lat["low_level"], tiny_lat[model],
                                         nthread=1)
            assert rollout.actions.shape == (task.num_episodes, task.num_steps, 2)
    assert_none_undeclared(mode)


def test_lib_exhaustive_evaluation_names_its_devices(tiny_lat):
    """LIB: exhaustive search over the experts (a finite action set, one-hot features) in closed loop."""
    from hierloco.components.com_model import train_com_model
    from hierloco.components.dynamics_data import collect_transitions
    from hierloco.components.low_level import ExpertReplayLowLevel
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.tasks import make_task
    from hierloco.pipeline.stages import evaluation_rollout

    with UndeclaredDevices() as mode:
        low_level = ExpertReplayLowLevel(tiny_lat["library"])
        env = LatentActionEnv(low_level, num_robots=4, seed=0, nthread=1)
        data = collect_transitions(env, 16, episode_length=2, seed=0, progress=False)
        env.close()
        model = train_com_model(data.com_state, low_level.action_features(data.action), data.next_com_state,
                                hidden=16, batch_size=8, max_epochs=2, device="cpu", progress=False)
        params = {"setting": "normal", "seed": 0, "device": "cpu", "planner": {"name": "exhaustive", "horizon": 2}}
        task = make_task("goal_reaching", **TASKS["goal_reaching"])
        rollout = evaluation_rollout(tiny_lat["robot"], params, task, low_level, model, nthread=1)
    assert rollout.actions.shape == (2, 2, 1)
    assert_none_undeclared(mode)


def test_sac_training_and_evaluation_name_their_devices(tiny_lat):
    """SAC's high level as its recipe runs it: the task env, the agent, ``train_sac`` (random frames, then the
    actor and updates from the replay buffer), a checkpoint and its resumption, and the evaluation."""
    from hierloco.components.evaluation import run_task
    from hierloco.components.policies import ActorPolicy
    from hierloco.components.sac import SACAgent, train_sac
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.tasks import make_task
    from hierloco.envs.transforms import GoalObservation
    from hierloco.recipes.sac.utils import task_env

    low_level = tiny_lat["low_level"]
    task = make_task("goal_reaching", **TASKS["goal_reaching"])
    with UndeclaredDevices() as mode:
        agent = SACAgent.build(GoalObservation.SIZE, low_level.action_low, low_level.action_high, hidden=16, seed=0,
                               device="cpu")
        env = task_env(low_level, task.training_split(), 4, 0, nthread=1)
        report = train_sac(env, agent, total_frames=24, init_random_frames=8, batch_size=8, buffer_size=64,
                           log_every=8, progress=False)
        env.close()
        env = LatentActionEnv(low_level, num_robots=task.num_episodes, record=True, seed=0, nthread=1)
        rollout = run_task(env, ActorPolicy(agent.actor_on("cpu")), task, transforms=[GoalObservation(task)])
        env.close()
    assert report["updates"] > 0 and rollout.actions.shape == (2, 2, 2)
    assert_none_undeclared(mode)


def test_sac_sac_low_level_names_its_devices():
    """SAC-SAC's low level: trained at 100 Hz on the velocity-command env, then run as a low level."""
    from hierloco.components.sac_low_level import SACLowLevel, command_grid, evaluate_velocity_tracking, \
        train_sac_low_level

    with UndeclaredDevices() as mode:
        trained = train_sac_low_level("a1", total_frames=48, num_robots=4, init_random_frames=16, batch_size=8,
                                      hidden=16, updates_per_frame=0.25, buffer_size=64, log_every=16, nthread=1,
                                      device="cpu", progress=False)
        report = evaluate_velocity_tracking(SACLowLevel(trained, steps_per_action=5, stochastic=True),
                                            command_grid("a1", 2)[:2], num_actions=2, settle_actions=1, nthread=1)
    assert trained.agent.updates > 0 and len(report["rows"]) == 2
    assert_none_undeclared(mode)


@pytest.mark.parametrize("planner", ["random_shooting", "cem", "mppi", "exhaustive"])
def test_planners_under_a_meta_default_device(tiny_lat, planner):
    """Every planner plans with its world model explicitly on the CPU while the default device is ``meta``: any
    tensor made along the way without a device would be a meta tensor and the call would fail. The actions equal
    those planned with the CPU as the default device."""
    from hierloco.components.planners import make_planner
    from hierloco.envs.tasks import make_task
    from hierloco.trained import make_world_model

    finite = planner == "exhaustive"
    if finite:
        from hierloco.components.low_level import ExpertReplayLowLevel

        low_level = ExpertReplayLowLevel(tiny_lat["library"])
        model = tiny_lat["mlp"].model.__class__(action_dim=low_level.num_choices, hidden=16)
    else:
        low_level, model = tiny_lat["low_level"], tiny_lat["mlp"].model
    task = make_task("goal_reaching", **TASKS["goal_reaching"])

    def plan() -> torch.Tensor:
        world_model = make_world_model(model, low_level, task=task, device="cpu")
        planning = make_planner(world_model, name=planner, seed=0, **PLANNER)
        state = world_model.initial_state(episode=torch.arange(2, device="cpu"))
        first = planning(state)["action"]
        moved = state.set("com_state", state["com_state"] + torch.tensor([0.1, 0.0, 0.0, 0.0, 0.0], device="cpu"))
        return torch.cat([first, planning(moved.set("task_step", moved["task_step"] + 1))["action"]])

    expected = plan()
    torch.set_default_device("meta")
    try:
        actions = plan()
    finally:
        torch.set_default_device(None)
    assert actions.device.type == "cpu"
    torch.testing.assert_close(actions, expected)
    if not finite:
        assert np.isfinite(actions.numpy()).all()


def test_evaluation_plans_every_robot_of_a_task_in_one_call_per_action(tiny_lat, monkeypatch):
    """Closed-loop evaluation batches the task's robots: one planner call per task step, over all its episodes at
    once (on a GPU: one transfer each way per action, not one per robot)."""
    from hierloco.components import evaluation
    from hierloco.envs.tasks import make_task
    from hierloco.pipeline import stages

    calls = []
    run_task = evaluation.run_task

    def counting(env, planner, task, **options):
        forward = planner.forward

        def counted(tensordict, *args, **kwargs):
            calls.append(tensordict.batch_size[0])
            return forward(tensordict, *args, **kwargs)

        planner.forward = counted
        return run_task(env, planner, task, **options)

    monkeypatch.setattr(evaluation, "run_task", counting)  # what the evaluation stage imports when it runs
    task = make_task("goal_reaching", num_goals=3, num_steps=2)
    params = {"setting": "normal", "seed": 0, "device": "cpu", "planner": {"name": "random_shooting", **PLANNER}}
    stages.evaluation_rollout(tiny_lat["robot"], params, task, tiny_lat["low_level"], tiny_lat["mlp"], nthread=1)
    assert calls == [task.num_episodes] * task.num_steps


@pytest.mark.parametrize("name, options", list(TASKS.items()))
def test_a_task_copies_its_targets_to_a_device_once(name, options):
    """A task keeps its constants on the CPU and one copy per device (``Task.on``): the targets a planner on another
    device indexes are already there (``meta`` stands for that device here), and its CPU side is unchanged."""
    from hierloco.envs.tasks import make_task

    task = make_task(name, **options)
    before = {key: value for key, value in vars(task).items() if isinstance(value, torch.Tensor)}
    task.to_device("meta")
    constants = [key for key in before]
    assert constants and all(task.on(key, "meta") is task.on(key, "meta") for key in constants)
    assert all(task.on(key, "meta").device.type == "meta" for key in constants)
    assert all(task.on(key, "cpu") is before[key] and getattr(task, key) is before[key] for key in constants)
    step = torch.zeros(2, dtype=torch.long, device="meta")
    assert task.target(step, step).device.type == "meta"

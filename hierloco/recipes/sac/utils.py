"""Factories of the SAC recipe: its plan of stages, the SAC high level (its env, its training, its evaluation) and
its config checks. The high level is shared with ``recipes/sac_sac``, whose low level differs (a SAC velocity policy
instead of ``pi(., z)``). Each task trains on its own ``training_split()``, half of its targets."""

from __future__ import annotations

from typing import TYPE_CHECKING

from hierloco.pipeline import config, report, stages
from hierloco.pipeline.config import make_task_from_spec, section, task_specs
from hierloco.pipeline.plan import Plan, Stage, TaskPlan
from hierloco.pipeline.rundir import digest
from hierloco.results import TaskEvaluation

if TYPE_CHECKING:  # the SAC parts are imported when a stage runs, not when the recipe plans
    from torchrl.envs import TransformedEnv

    from hierloco.components.sac import SACAgent
    from hierloco.envs.tasks import Task

METHOD = "sac"


def checks(c: config.Checker, robot) -> None:
    config.check_experts(c, robot)
    config.check_policy(c)
    check_high_level(c)


def check_high_level(c: config.Checker) -> None:
    """The checks of the SAC high level (this recipe's and SAC-SAC's), its tasks and its logger."""
    config.check_eval(c)
    config.check_logger(c)
    for key in ("sac.total_frames", "sac.num_robots", "sac.batch_size", "sac.hidden", "sac.buffer_size"):
        c.integer(key)
    c.integer("sac.init_random_frames", minimum=0)
    for key in ("sac.lr", "sac.updates_per_frame", "sac.tau"):
        c.positive(key)
    c.fraction("sac.gamma")
    if not isinstance(config.get(c.cfg, "sac.compile", False), bool):
        c.fail(f"sac.compile must be true or false, got {config.get(c.cfg, 'sac.compile')!r}")
    if list(c.cfg.settings) != ["normal"]:
        c.fail(f"the SAC high level runs the normal setting only, got settings={list(c.cfg.settings)}")


def plan(cfg, robot) -> Plan:
    """Experts -> gait policy -> its check -> the SAC high level per main task, over z."""
    from hierloco.envs.robots import robot_fingerprint

    experts = stages.experts_stage(cfg, robot_fingerprint(robot))
    policy = stages.gait_policy_stage(cfg, experts)
    return Plan(experts=experts, gait_policy=policy, gait_policy_check=stages.gait_policy_check_stage(cfg, policy),
                tasks=high_level_stages(cfg, stages.latent_low_level(policy)))


def high_level_stages(cfg, low_level: dict) -> list[TaskPlan]:
    """Per main task a SAC agent (``sac_<task>``), then its evaluation on its own task and on the generalisation
    variants of the same kind; when two main tasks are of one kind (the fair targets' ``trajectory_tracking`` and
    ``trajectory_tracking_fast``, docs/tasks.md), each agent is evaluated on its own task and the variants go to the
    first of them, so every evaluation is made once, by one agent."""
    planned = []
    specs = task_specs(cfg)
    main = list(cfg.eval.tasks)
    first_of_kind: dict = {}
    for name in main:
        first_of_kind.setdefault(task_kind(name, specs[name]), name)
    for name in main:
        agent = sac_stage(cfg, name, specs[name], low_level)
        kind = task_kind(name, specs[name])
        evaluated = [name] + [other for other, spec in specs.items() if other not in main
                              and task_kind(other, spec) == kind and first_of_kind[kind] == name]
        evaluations = [sac_evaluation_stage(cfg, other, specs[other], agent)
                       for other in specs if other in evaluated]  # in the config's order, as before
        planned.append(TaskPlan(name, agent, evaluations))
    return planned


def task_kind(name: str, spec: dict) -> str:
    return (spec or {}).get("task", name)


def sac_stage(cfg, name: str, spec: dict, low_level: dict) -> Stage:
    """The SAC agent of task ``name``, trained on its training split whichever split is evaluated (``split: train``
    evaluates the training targets only, as tuning does: the same agent, so its key leaves the split out)."""
    trained_on = {k: v for k, v in spec.items() if k != "split" and k not in config.WORLD_KEYS}
    params = {"seed": cfg.seed, "device": stages.training_device(cfg), "task_name": name, "task": trained_on,
              **sac_params(cfg), **config.world(cfg, "training").params()}  # terrain, randomization: docs/terrain.md
    return Stage(f"sac_{name}", params, {"low_level": low_level}, f"sac_{name}.pt", "hierloco.components.sac:SACAgent",
                 train_high_level)


SAC_DEFAULTS = {"compile": False}  # options added later: keyed only when they differ (docs/pipeline.md)


def sac_params(cfg) -> dict:
    """The ``sac`` section as a SAC stage's key holds it: every option it always held, and ``compile`` only when
    it is on (:func:`hierloco.registry.without_defaults`), so runs and records made before it keep their keys."""
    from hierloco.registry import without_defaults

    return without_defaults(section(cfg, "sac"), SAC_DEFAULTS)


def sac_evaluation_stage(cfg, name: str, spec: dict, agent: Stage) -> Stage:
    params = {"seed": cfg.seed, "setting": "normal", "task_name": name, **stages.evaluation_params(cfg, name, spec)}
    after = {"agent": agent.digest}
    key_digest = digest({"params": params, "after": after})
    return Stage(f"evaluation_normal_{name}", params, after, f"evaluation/normal/{name}-{key_digest}.npz",
                 TaskEvaluation, build_evaluation)


def task_env(low_level, task: Task, num_robots: int, seed: int, nthread: int | None = None,
             world=None) -> TransformedEnv:
    """``num_robots`` robots on ``task``, robot ``b`` on episode ``b % episodes``, with the goal observation, in
    ``world`` (a :class:`hierloco.pipeline.config.World`; default flat, nominal)."""
    import torch
    from torchrl.envs import Compose, TransformedEnv

    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.transforms import GoalObservation, task_transforms

    episodes = torch.arange(num_robots, device="cpu") % task.num_episodes
    env = LatentActionEnv(low_level, num_robots=num_robots, seed=seed, nthread=nthread,
                          **(world.options() if world is not None else {}))
    return TransformedEnv(env, Compose(task_transforms(task, episodes), GoalObservation(task)))


def train_high_level(run, params, make_low_level) -> SACAgent:
    """Goal-conditioned SAC (TorchRL's ``SACLoss``, :func:`hierloco.components.sac.train_sac`) on the training half
    of a task's targets, ``total_frames`` high-level actions collected on ``num_robots`` robots at once.

    Checkpointed as it trains (``sac_<task>.training.pt`` in the run directory, every tenth of ``total_frames``), so
    a killed run resumes from its last checkpoint (a checkpoint of other parameters is refused); the checkpoint is
    removed once the agent is trained."""
    from hierloco.components.sac import SACAgent, train_sac
    from hierloco.envs.transforms import GoalObservation

    task = make_task_from_spec(params["task_name"], params["task"]).training_split()
    low_level = make_low_level(params["num_robots"])
    agent = SACAgent.build(GoalObservation.SIZE, low_level.action_low, low_level.action_high, hidden=params["hidden"],
                           lr=params["lr"], gamma=params["gamma"], tau=params["tau"], seed=params["seed"],
                           device=params["device"], compile_update=params.get("compile", False))
    env = task_env(low_level, task, params["num_robots"], params["seed"], nthread=run.nthread,
                   world=stages.stage_world(run, params, "training"))
    checkpoint = run.path / f"sac_{params['task_name']}.training.pt"
    try:
        agent.metadata = train_sac(env, agent, total_frames=params["total_frames"],
                                   init_random_frames=params["init_random_frames"],
                                   updates_per_frame=params["updates_per_frame"], batch_size=params["batch_size"],
                                   buffer_size=params["buffer_size"], log_every=max(params["num_robots"],
                                                                                    params["total_frames"] // 20),
                                   seed=params["seed"], progress=run.progress, logger=run.logger,
                                   tag=f"sac_{params['task_name']}", checkpoint_path=checkpoint,
                                   checkpoint_every=max(params["num_robots"], params["total_frames"] // 10),
                                   settings=params)
    finally:
        env.close()
    run.dir.count_interrupted_seconds(agent.metadata["seconds"]["before_resume"])
    checkpoint.unlink(missing_ok=True)  # the training state (with its replay buffer) is not needed any more
    return agent


def build_evaluation(run, params, agent: SACAgent, make_low_level) -> TaskEvaluation:
    """The trained policy (its mean action) on every target of a task, one robot per episode. It acts on the CPU
    whatever the device it was trained on (the key holds no device): the agent just trained and the one loaded
    from its checkpoint act alike."""
    from hierloco.components.evaluation import run_task
    from hierloco.components.policies import ActorPolicy
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.envs.transforms import GoalObservation

    task = make_task_from_spec(params["task_name"], params["task"])
    world = stages.stage_world(run, params, "evaluation")
    env = LatentActionEnv(make_low_level(task.num_episodes), num_robots=task.num_episodes, record=True,
                          seed=params["seed"], nthread=run.nthread, obstacles=task.obstacles, **world.options())
    try:
        rollout = run_task(env, ActorPolicy(agent.actor_on("cpu")), task, transforms=[GoalObservation(task)],
                           progress=run.progress)
    finally:
        env.close()
    evaluation = report.task_evaluation(rollout, task, method=run.method, robot=run.robot.name, setting="normal",
                                        seed=params["seed"])
    return stages.world_evaluation(evaluation, rollout, task, world, steps_per_action=run.cfg.steps_per_action)


def manifest(cfg, robot) -> dict:
    return {"low_level": {"kind": "latent"}}


def make_low_level(run, trained):
    """``pi(., z)``: one stateless low level serves any number of robots."""
    from hierloco.components.low_level import LatentLowLevel

    low_level = LatentLowLevel(trained, run.robot, device=run.cfg.device)
    return lambda num_robots: low_level

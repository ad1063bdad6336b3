"""The stages of the model-based pipeline (LAT, LIB, IK, and the LAT low level of SAC), each a cached artifact.

A :class:`Stage` has ``params`` (the values its builder is called with: config values, nothing else) and ``after``
(the digests of what it depends on: the robot's fingerprint and the upstream stages), which together are its key.
A builder receives only ``params`` (and the upstream artifacts), so everything that changes an artifact is in its
key by construction. The ``*_stage`` functions make stages from the config; the ``build_*`` functions build them.

Stages, in order (see ``docs/index.md`` for the paper's steps):

- ``experts``: the expert library (Li et al., Sec. III-A);
- ``gait_policy``, ``gait_policy_check``: the latent gait policy and its check in simulation (Sec. III-B);
- ``dynamics_data_<setting>``, ``dynamics_model_<setting>``: CoM dynamics data and model (Sec. III-C);
- ``evaluation_<setting>_<task>``: closed-loop MPC on one task (Sec. III-D, IV).
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

import numpy as np

from omegaconf import OmegaConf

from hierloco.envs.faults import fault_legs, is_unadapted, physical_setting, setting_robot
from hierloco.envs.robots import CONTROL_TIMESTEP, hardware_options
from hierloco.errors import Finding
from hierloco.pipeline import report
from hierloco.pipeline.config import (WORLD_KEYS, World, get, make_task_from_spec, make_world, section, task_specs,
                                      world)
from hierloco.pipeline.plan import JsonReport, SettingPlan, Stage
from hierloco.pipeline.rundir import digest
from hierloco.results import TaskEvaluation

if TYPE_CHECKING:
    from hierloco.components.com_model import TrainedCoMModel
    from hierloco.components.dynamics_data import TransitionData
    from hierloco.components.expert_library import ExpertLibrary
    from hierloco.components.gait_policy import TrainedGaitPolicy

# A recipe imports this module to plan its stages, before any work (and a study plans every job's stages): so
# planning needs no network or TorchRL library, and the builders import theirs when they run.


class GaitPolicyCheck(JsonReport):
    SCHEMA = {"reproduction_error": list, "reproduced_fraction": float, "interpolation_walks": float,
              "interpolation_between": float}


class LatentContinuity(JsonReport):
    """CoM velocities over a lattice of latents and how continuously they vary
    (:func:`hierloco.components.evaluation.latent_continuity`)."""

    SCHEMA = {"grid": int, "latent_dim": int, "num_actions": int, "latents": list, "velocity": list, "fell": list,
              "neighbour_difference": float, "pair_difference": float, "ratio": float, "neighbour_pairs": int,
              "pairs": int, "fell_fraction": float}


class GaitPolicyQualityError(Finding, ValueError):
    """The latent gait policy does not reproduce enough of its experts in simulation."""


# ---------------------------------------------------------------------------------------------------- experts
# Options added after runs were recorded, keyed only when they differ from these defaults (docs/pipeline.md).
EXPERTS_DEFAULTS = {"tune": False, "tune_budget": 300.0, "gaits": None, "gait_boxes": None, "max_failed_experts": None,
                    "swing_height_m": None}
POLICY_DEFAULTS = {"adaptive": False, "budget_epochs": None}


def experts_stage(cfg, robot_digest: str) -> Stage:
    from hierloco.registry import without_defaults

    params = {"seed": cfg.seed, "steps_per_action": cfg.steps_per_action,
              **without_defaults(section(cfg, "experts"), EXPERTS_DEFAULTS)}
    return Stage("experts", params, {"robot": robot_digest}, "experts.npz",
                 "hierloco.components.expert_library:ExpertLibrary", build_experts,
                 check_experts)


def build_experts(run, params) -> ExpertLibrary:
    """The expert library, checked to walk as commanded (Li et al., Sec. III-A)."""
    from hierloco.components.expert_library import build_expert_library

    options = {"steps_per_action": params["steps_per_action"], "seed": params["seed"],
               "settle_time": params["settle_time"], "command_low": params.get("command_low"),
               "command_high": params.get("command_high"), "progress": run.progress,
               "max_failed_experts": params.get("max_failed_experts"),
               "swing_height_m": params.get("swing_height_m")}
    with warnings.catch_warnings():  # check_experts raises with the same diagnosis, in one line
        warnings.filterwarnings("ignore", message=".*do not walk as commanded", category=RuntimeWarning)
        if params.get("gaits"):  # experts over several gaits, one gait policy over all (hierloco.components.gaits)
            from hierloco.components.gaits import build_gait_library

            return build_gait_library(run.robot, params["gaits"], params["num_experts"],
                                      gait_boxes=params.get("gait_boxes"), **options)
        return build_expert_library(run.robot, params["num_experts"], **options)


def check_experts(run, library: ExpertLibrary) -> None:
    """Stops the run (:class:`ExpertQualityError`, with a diagnosis) when the experts do not cover the command
    box: how far off, in which direction, what to try."""
    from hierloco.components.expert_library import require_expert_library_quality

    require_expert_library_quality(library, robot=run.robot, min_reach=run.cfg.checks.min_expert_reach)


# ---------------------------------------------------------------------------------------------------- gait policy
def training_device(cfg) -> str:
    """The device the training stages were (or are) made on: ``device``, or when ``recipes/evaluate.py`` evaluates a
    run on another device, the one it was trained on (``trained_device``), so the trained stages keep their keys
    while the evaluations record the device they run on (``docs/gpu.md``)."""
    return str(cfg.get("trained_device") or cfg.device)


def gait_policy_stage(cfg, experts: Stage) -> Stage:
    """The gait policy; with ``policy.adaptive=true`` it is fitted by :func:`hierloco.components.gait_policy.
    fit_gait_policy` (longer, wider, a lower learning rate until it reproduces ``checks.min_reproduced_fraction`` of
    the experts, within ``policy.budget_epochs``), and only then does its key hold those options and the bar."""
    from hierloco.registry import without_defaults

    policy = without_defaults(section(cfg, "policy"), POLICY_DEFAULTS)
    if policy.get("adaptive"):
        policy["min_reproduced_fraction"] = cfg.checks.min_reproduced_fraction
    params = {"seed": cfg.seed, "device": training_device(cfg), **policy}
    return Stage("gait_policy", params, {"experts": experts.digest}, "gait_policy.pt",
                 "hierloco.components.gait_policy:TrainedGaitPolicy",
                 build_gait_policy)


def build_gait_policy(run, params, library: ExpertLibrary) -> TrainedGaitPolicy:
    """``pi(t, z)`` and one latent per expert, fitted jointly to the experts (Li et al., Sec. III-B)."""
    from hierloco.components.gait_policy import train_gait_policy
    from hierloco.envs.locomotion import periods_per_action

    periods = periods_per_action(run.robot, library.steps_per_action)
    fit_options = {key: params[key] for key in ("adaptive", "budget_epochs", "min_reproduced_fraction") if key in params}
    train = {key: value for key, value in params.items() if key not in fit_options}
    if fit_options.pop("adaptive", False):
        from hierloco.components.gait_policy_fit import fit_gait_policy

        fit = fit_gait_policy(library, robot=run.robot, periods_per_action=periods, progress=run.progress,
                              **fit_options, **train)
        trained = fit.trained
        if not fit.ok and fit.limited_by_experts:
            print("the experts' own targets reproduce too few of them for any fit: hierloco-robot-check searches "
                  "expert parameters that walk")
    else:
        trained = train_gait_policy(library.joint_targets, periods_per_action=periods, progress=run.progress, **train)
    run.logger.log_curve("train/gait_policy", {"loss": trained.metadata["loss_history"]}, step_name="epoch")
    run.logger.log_scalar("train/gait_policy/rmse", trained.metadata["rmse"], step=len(trained.metadata["loss_history"]))
    return trained


def gait_policy_check_stage(cfg, policy: Stage) -> Stage:
    return Stage("gait_policy_check", {"seed": cfg.seed, "num_pairs": 50, "num_actions": 4},
                 {"gait_policy": policy.digest}, "gait_policy_check.json", GaitPolicyCheck, build_gait_policy_check,
                 check_gait_policy_reproduction)


def build_gait_policy_check(run, params, low_level, library: ExpertLibrary) -> GaitPolicyCheck:
    """Reproduction of every expert and interpolation between pairs by ``pi(., z)``, in simulation."""
    from hierloco.components.evaluation import check_gait_policy

    latents = low_level.trained.latents.numpy()
    return GaitPolicyCheck(check_gait_policy(low_level, library, latents, **params))


def check_gait_policy_reproduction(run, check: GaitPolicyCheck) -> None:
    """Stops the run when ``pi(., z_g)`` reproduces fewer than ``checks.min_reproduced_fraction`` of the experts."""
    wanted = run.cfg.checks.min_reproduced_fraction
    if check["reproduced_fraction"] < wanted:
        errors = np.asarray(check["reproduction_error"], dtype=float)
        raise GaitPolicyQualityError(
            f"the gait policy reproduces {100 * check['reproduced_fraction']:.0f}% of the experts within 0.05 m/s in "
            f"simulation (need {100 * wanted:.0f}%; median error {np.median(errors):.2f} m/s, worst "
            f"{np.max(errors):.2f} m/s, {int(np.isinf(errors).sum())} fell): train it longer (policy.epochs) or "
            "wider (policy.hidden), or let the experts settle longer (experts.settle_time); "
            "checks.min_reproduced_fraction sets the bar")


def latent_continuity_stage(cfg, policy: Stage) -> Stage | None:
    """The optional measurement of how continuously the latent space maps to CoM motion (Sec. III-B, Fig. 4),
    planned only when ``eval.latent_continuity`` is set (``{grid: 7, num_actions: 3}``), so runs without it keep
    their plans and keys."""
    options = cfg.eval.get("latent_continuity")
    if not options:
        return None
    params = {"seed": cfg.seed, "grid": int(options.get("grid", 7)), "num_actions": int(options.get("num_actions", 3))}
    return Stage("latent_continuity", params, {"gait_policy": policy.digest}, "latent_continuity.json",
                 LatentContinuity, build_latent_continuity)


def build_latent_continuity(run, params, low_level) -> LatentContinuity:
    from hierloco.components.evaluation import latent_continuity

    return LatentContinuity(latent_continuity(low_level, **params))


def latent_low_level(policy: Stage) -> dict:
    """The key of LAT's low level ``pi(., z)``: the gait policy it runs."""
    return {"kind": "latent", "gait_policy": policy.digest}


# ---------------------------------------------------------------------------------------------------- dynamics
DATA_KEYS = ("num_transitions", "num_robots", "episode_length")
MODEL_KEYS = ("hidden", "lr", "batch_size", "holdout", "patience", "max_epochs")


def hardware_params(cfg, setting: str) -> dict:
    """``{"hardware": options}`` for the settings that simulate the perturbed robot (the options of
    :func:`hierloco.envs.robots.hardware.perturbed`, ``hardware.*`` in the config over its defaults), else ``{}``."""
    if physical_setting(setting) != "hardware":
        return {}
    return {"hardware": hardware_options(**(OmegaConf.to_container(cfg.hardware, resolve=True)
                                            if cfg.get("hardware") is not None else {}))}


def dynamics_data_stage(cfg, low_level: dict, setting: str, robot) -> Stage:
    """The CoM dynamics data of ``setting``, collected in the setting's world (``terrain``, ``randomization``, and
    ``hardware_world.*`` for the "hardware" robot; keyed only when not flat and nominal:
    :class:`hierloco.pipeline.config.World`)."""
    d = section(cfg, "dynamics")
    locked, limp = fault_legs(robot, setting)
    params = {"seed": cfg.seed, "setting": setting, "disabled_legs": list(locked), "limp_legs": list(limp),
              **{k: d[k] for k in DATA_KEYS}, **hardware_params(cfg, setting), **world(cfg, "data", setting=setting).params()}
    return Stage(f"dynamics_data_{setting}", params, {"low_level": low_level},
                 f"dynamics_data_{setting}.npz", "hierloco.components.dynamics_data:TransitionData",
                 build_dynamics_data)


def build_dynamics_data(run, params, make_low_level) -> TransitionData:
    """Random actions held for one action each, chained on many robots (Li et al., Sec. III-C)."""
    from hierloco.components.dynamics_data import collect_transitions
    from hierloco.envs.latent_env import LatentActionEnv

    env = LatentActionEnv(make_low_level(params["num_robots"]), num_robots=params["num_robots"],
                          disabled_legs=params["disabled_legs"], limp_legs=params["limp_legs"], seed=params["seed"],
                          nthread=run.nthread,
                          robot=setting_robot(run.robot, params["setting"], params.get("hardware")),
                          **stage_world(run, params, "data").options())
    try:
        return collect_transitions(env, params["num_transitions"], episode_length=params["episode_length"],
                                   seed=params["seed"], progress=run.progress)
    finally:
        env.close()


def model_params(cfg) -> dict:
    """The dynamics model's options as a stage key holds them: the training keys it always held
    (:data:`MODEL_KEYS`), then ``model`` and that model's own options only where they differ from the defaults
    (the registry's ``mlp``: so runs and records made before the registry keep their keys)."""
    from hierloco.components.com_model import MODELS
    from hierloco.registry import without_defaults

    d = section(cfg, "dynamics")
    name = d.get("model", "mlp")
    own = {key: value for key, value in MODELS.select(name, d).items() if key not in MODEL_KEYS}
    defaults = {"model": "mlp", **{key: value for key, value in MODELS.options(name).items()
                                   if key not in MODEL_KEYS}}
    return {**{k: d[k] for k in MODEL_KEYS}, **without_defaults({"model": name, **own}, defaults)}


def dynamics_model_stage(cfg, data: Stage, setting: str) -> Stage:
    """The CoM model of ``setting``; with ``dynamics.body_state=true`` it also reads what the trunk feels of the
    ground at the action's start (roll, pitch, height: :data:`hierloco.trained.BODY_CONTEXT`), keyed only then."""
    params = {"seed": cfg.seed, "device": training_device(cfg), "duration": cfg.steps_per_action * CONTROL_TIMESTEP,
              **model_params(cfg), **({"body_state": True} if section(cfg, "dynamics").get("body_state") else {})}
    return Stage(f"dynamics_model_{setting}", params, {"data": data.digest}, f"dynamics_model_{setting}.pt",
                 "hierloco.components.com_model:TrainedCoMModel", build_dynamics_model)


def build_dynamics_model(run, params, data: TransitionData, low_level) -> TrainedCoMModel:
    """The local-frame delta model ``(dx, dy, dyaw, vx', vy') = f(vx, vy, a)``, early-stopped on held-out data."""
    from hierloco.components.com_model import train_com_model

    from hierloco.trained import BODY_CONTEXT

    params = dict(params)
    context = BODY_CONTEXT if params.pop("body_state", False) else {}
    features = low_level.action_features(data.action)
    if context:  # the body state at each action's start, after the action's features (CoMWorldModelEnv's context)
        if data.body_state is None:
            raise ValueError(f"{run.current}: dynamics.body_state needs dynamics data that recorded the body state; "
                             "this data was collected before it was")
        features = np.concatenate([np.asarray(features, dtype=np.float64), data.body_state], -1)
    model = train_com_model(data.com_state, features, data.next_com_state, progress=run.progress, **params)
    if context:
        model.metadata["context"] = dict(context)
    setting = run.current.removeprefix("dynamics_model_")
    curves = {"heldout_loss": model.metadata["heldout_loss_history"],
              "train_loss": model.metadata["train_loss_history"]}
    run.logger.log_curve(f"train/dynamics_{setting}", curves, step_name="epoch")
    return model


# ---------------------------------------------------------------------------------------------------- evaluation
def evaluation_stage(cfg, name: str, spec: dict, setting: str, model: Stage, low_level: dict) -> Stage:
    """MPC on one task; cached per task and planner (the file name carries the key's digest), in the task's world
    (:func:`evaluation_params`)."""
    replan = get(cfg, "eval.replan_steps")  # keyed only when set: every other key is as it was
    params = {"seed": cfg.seed, "device": cfg.device, "setting": setting, "task_name": name,
              "planner": planner_params(cfg), **hardware_params(cfg, setting),
              **evaluation_params(cfg, name, spec, setting),
              **({"replan_steps": int(replan)} if replan not in (None, cfg.steps_per_action) else {})}
    after = {"model": model.digest, "low_level": low_level}
    key_digest = digest({"params": params, "after": after})
    return Stage(f"evaluation_{setting}_{name}", params, after, f"evaluation/{setting}/{name}-{key_digest}.npz",
                 TaskEvaluation, build_evaluation)


# The planner options every evaluation key has always held; any other option enters the key only when it differs from
# its default, so adding an option keeps the keys of finished runs and committed records (docs/pipeline.md).
PLANNER_KEYS = ("name", "horizon", "num_candidates", "optim_steps", "top_k", "temperature")
WORLD_MODEL_DEFAULTS = {"risk": "none", "beta": 1.0}  # how the world model scores a plan (planner.risk, .beta)


def planner_params(cfg) -> dict:
    """The ``planner`` section as an evaluation's key holds it (see :data:`PLANNER_KEYS`)."""
    from hierloco.components.planners import PLANNERS, SCORING_DEFAULTS
    from hierloco.registry import without_defaults

    values = section(cfg, "planner")
    defaults = {**PLANNERS.options(values["name"]), **WORLD_MODEL_DEFAULTS, **SCORING_DEFAULTS}
    return without_defaults(values, defaults, keep=PLANNER_KEYS)


def build_evaluation(run, params, make_low_level, model: TrainedCoMModel) -> TaskEvaluation:
    """Closed-loop MPC on every episode of a task, one robot per episode, re-planning after every action."""
    task = make_task_from_spec(params["task_name"], params["task"])
    world_ = stage_world(run, params, "evaluation")
    rollout = evaluation_rollout(run.robot, params, task, make_low_level(task.num_episodes), model,
                                 nthread=run.nthread, progress=run.progress, world=world_)
    evaluation = report.task_evaluation(rollout, task, method=run.method, robot=run.robot.name,
                                        setting=params["setting"], seed=params["seed"])
    return world_evaluation(evaluation, rollout, task, world_, steps_per_action=run.cfg.steps_per_action)


def evaluation_params(cfg, name: str, spec: dict, setting: str | None = None) -> dict:
    """What an evaluation's key holds of its task (``task``: its type and options, without its world) and of the
    world it runs in, in ``setting`` (:func:`hierloco.pipeline.config.world`: ``terrain``, ``pushes``,
    ``randomization``, each only when it is not the default, so flat evaluations keep their keys). Shared by every
    method's evaluations."""
    return {"task": {key: value for key, value in spec.items() if key not in WORLD_KEYS},
            **world(cfg, "evaluation", name, setting).params()}


def stage_world(run, params: dict, part: str) -> World:
    """The world a stage simulates in (``part``: ``data``, ``training`` or ``evaluation``), built from the run's
    config (a terrain file read again; in the stage's ``setting``) and checked to be the one its key holds
    (``params``)."""
    built = world(run.cfg, part, params.get("task_name") if part == "evaluation" else None, params.get("setting"))
    keyed = {key: params[key] for key in WORLD_KEYS if key in params}
    if built.params() != keyed:
        raise RuntimeError(f"the {part} world of the config ({built.params()}) is not the stage's ({keyed})")
    return built


def world_evaluation(evaluation: TaskEvaluation, rollout, task, world_: World, *,
                     steps_per_action: int) -> TaskEvaluation:
    """``evaluation`` with what the world did, when it is not the default (flat, no pushes, nominal: the evaluation
    as it was): per episode ``fell`` (and with pushes ``pushes``, ``push_falls``, ``recovery_s``), the summary
    (``fall_rate``, ``push_fall_rate``, ``recovery_s``, ...: :func:`hierloco.components.evaluation.world_metrics`)
    and the world in its metadata."""
    if world_.is_default:
        return evaluation
    from hierloco.components.evaluation import world_metrics

    per_episode, summary = world_metrics(rollout, task, steps_per_action=steps_per_action,
                                         pushes=world_.pushes.active)
    for index, row in enumerate(evaluation.rows):
        row.update({name: float(values[index]) for name, values in per_episode.items()})
    evaluation.metrics.update(summary)
    evaluation.metadata.update({"world": world_.describe(), **world_.params()})
    return evaluation


def evaluation_rollout(robot, params: dict, task, low_level, model: TrainedCoMModel, *, nthread=None,
                       progress: bool = False, world: World | None = None):
    """The :class:`~hierloco.components.evaluation.TaskRollout` of an evaluation stage's ``params`` (setting,
    planner, seed, device, hardware, world): what :func:`build_evaluation` scores, and what
    ``recipes/adverse/trace.py`` replays from a finished run's evaluation key. ``world``: the built world
    (:func:`stage_world`; default: made from the key, which a terrain file's key cannot: its path is not in it)."""
    from hierloco.components.evaluation import run_task
    from hierloco.components.planners import make_planner
    from hierloco.envs.latent_env import LatentActionEnv
    from hierloco.trained import make_world_model

    world_model = make_world_model(model, low_level, device=params["device"])
    planner_section = params["planner"]
    world_model.set_risk(planner_section.get("risk", "none"), planner_section.get("beta", 1.0))
    planner = make_planner(world_model, seed=params["seed"], **params["planner"])
    locked, limp = fault_legs(robot, params["setting"])
    if world is None:
        world = make_world({key: params.get(key) for key in WORLD_KEYS})
    env = LatentActionEnv(low_level, num_robots=task.num_episodes, disabled_legs=locked, limp_legs=limp,
                          record=True, seed=params["seed"], nthread=nthread, obstacles=task.obstacles,
                          robot=setting_robot(robot, params["setting"], params.get("hardware")),
                          replan_steps=params.get("replan_steps"), **world.options())
    try:
        return run_task(env, planner, task, progress=progress)
    finally:
        env.close()


# ---------------------------------------------------------------------------------------------------- helpers
def per_setting_stages(cfg, low_level: dict, robot) -> list[SettingPlan]:
    """The model-based part of a plan, for every setting whose CoM dynamics are learned: dynamics data on the low
    level, the CoM model, and the evaluations that plan with it (LAT, LIB and IK share it; only their low level
    differs). A ``<setting>_unadapted`` setting plans with the normal setting's model, so ``normal`` is then learned
    first even when it is not evaluated."""
    planned: dict[str, SettingPlan] = {}
    learned = [s for s in cfg.settings if not is_unadapted(s)]
    if len(learned) < len(cfg.settings) and "normal" not in learned:
        learned.insert(0, "normal")
    for setting in learned:
        data = dynamics_data_stage(cfg, low_level, setting, robot)
        model = dynamics_model_stage(cfg, data, setting)
        planned[setting] = SettingPlan(setting, data, model,
                                       evaluation_stages(cfg, setting, model, low_level) if setting in cfg.settings
                                       else [])
    for setting in cfg.settings:
        if is_unadapted(setting):
            normal = planned["normal"]
            normal.evaluations += evaluation_stages(cfg, setting, normal.model, low_level)
    return list(planned.values())


def evaluation_stages(cfg, setting: str, model: Stage, low_level: dict) -> list[Stage]:
    return [evaluation_stage(cfg, name, spec, setting, model, low_level) for name, spec in task_specs(cfg).items()]

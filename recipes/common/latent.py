"""The LAT low level for recipes (LAT, SAC): the expert library, the latent gait policy and its check, cached."""

from __future__ import annotations

from common import pipeline
from hierloco.components.evaluation import check_gait_policy
from hierloco.components.expert_library import ExpertLibrary
from hierloco.components.gait_policy import TrainedGaitPolicy, train_gait_policy
from hierloco.components.low_level import LatentLowLevel
from hierloco.envs.robots import CONTROL_TIMESTEP, get_robot
from hierloco.runs import RunDirectory


def policy_config(cfg) -> dict:
    return {"experts": pipeline.experts_config(cfg), **pipeline.section(cfg, "policy")}


def stage_gait_policy(cfg, run: RunDirectory, library: ExpertLibrary) -> TrainedGaitPolicy:
    robot = get_robot(cfg.robot)
    periods = int(round(library.steps_per_action * CONTROL_TIMESTEP / robot.gait_period))
    p = cfg.policy

    def build():
        return train_gait_policy(library.joint_targets, latent_dim=p.latent_dim, periods_per_action=periods,
                                 num_harmonics=p.num_harmonics, hidden=p.hidden, epochs=p.epochs,
                                 batch_size=p.batch_size, lr=p.lr, latent_lr=p.latent_lr,
                                 latent_weight_decay=p.latent_weight_decay, seed=cfg.seed, device=cfg.device,
                                 progress=cfg.progress)
    return run.stage("gait_policy", policy_config(cfg), build, lambda t, path: t.save(path), TrainedGaitPolicy.load,
                     "gait_policy.pt")


def stage_gait_policy_check(cfg, run: RunDirectory, low_level, library: ExpertLibrary,
                            trained: TrainedGaitPolicy) -> dict:
    """Reproduction of the experts and interpolation between them by ``pi(., z)``, in simulation."""
    return run.stage("gait_policy_check", policy_config(cfg),
                     lambda: check_gait_policy(low_level, library, trained.latents.numpy(), seed=cfg.seed),
                     pipeline.save_json, pipeline.load_json, "gait_policy_check.json")


def prepare(cfg, run: RunDirectory, logger, reports: dict) -> pipeline.LowLevelRecipe:
    """Experts -> latent gait policy -> its check; the low level is ``pi(., z)``."""
    library = pipeline.stage_experts(cfg, run)
    trained = stage_gait_policy(cfg, run, library)
    low_level = LatentLowLevel(trained, cfg.robot, device=cfg.device)
    check = stage_gait_policy_check(cfg, run, low_level, library, trained)
    reports.update(experts=library.metadata, gait_policy=trained.metadata, gait_policy_check=check)
    logger.log_metrics({"train/gait_policy/rmse": trained.metadata["rmse"],
                        "eval/gait_policy/reproduced_fraction": check["reproduced_fraction"],
                        "eval/gait_policy/interpolation_walks": check["interpolation_walks"],
                        "eval/gait_policy/interpolation_between": check["interpolation_between"]})
    return pipeline.LowLevelRecipe(make=lambda num_robots: low_level, config={"policy": policy_config(cfg)})

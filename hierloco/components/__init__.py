"""Reusable parts of the hierarchy (Li et al., RA-L 2021, Sec. III; ``docs/index.md`` maps them to the paper).

- ``kinematics``: generic leg FK/IK from the MuJoCo model. ``experts``: the Raibert footstep controller.
- ``expert_library``: recorded expert gaits. ``gait_policy``: the latent gait policy ``pi(t, z)``.
- ``low_level``: latent, expert-replay and command low levels. ``dynamics_data``: random-action transitions.
- ``com_model``: the local-frame CoM dynamics model and the registry of models (``MODELS``: ``mlp``, ``ensemble``).
  ``com_ensemble``: the probabilistic ensemble (PETS). ``planners``: random shooting, CEM, MPPI, exhaustive MPC.
- ``policies``: the task-policy protocol of closed-loop evaluation. ``evaluation``: closed-loop task episodes and
  gait-policy checks. ``sac``: the SAC agent and its batched training loop. ``sac_low_level``: SAC-SAC's 100 Hz
  velocity-tracking low level and its tracking evaluation.

The names below load their module on first use, so importing one submodule (``hierloco.envs.faults``,
``hierloco.components.com_model``) does not import the rest.
"""

from __future__ import annotations

from hierloco._lazy import lazy_names

_WHERE = {
    "ActorPolicy": "hierloco.components.policies",
    "BoxCEMPlanner": "hierloco.components.planners",
    "BoxMPPIPlanner": "hierloco.components.planners",
    "BoxPlannerBase": "hierloco.components.planners",
    "CoMDynamicsModel": "hierloco.components.com_model",
    "CoMEnsembleModel": "hierloco.components.com_ensemble",
    "CommandLowLevel": "hierloco.components.low_level",
    "ExhaustivePlanner": "hierloco.components.planners",
    "ExpertLibrary": "hierloco.components.expert_library",
    "ExpertReplayLowLevel": "hierloco.components.low_level",
    "LatentGaitPolicy": "hierloco.components.gait_policy",
    "LatentLowLevel": "hierloco.components.low_level",
    "LegKinematics": "hierloco.components.kinematics",
    "LowLevel": "hierloco.components.low_level",
    "MODELS": "hierloco.components.com_model",
    "PLANNERS": "hierloco.components.planners",
    "RaibertController": "hierloco.components.experts",
    "RandomShootingPlanner": "hierloco.components.planners",
    "SACAgent": "hierloco.components.sac",
    "SACLowLevel": "hierloco.components.sac_low_level",
    "TaskPolicy": "hierloco.components.policies",
    "TaskRollout": "hierloco.components.evaluation",
    "TrainedCoMModel": "hierloco.components.com_model",
    "TrainedGaitPolicy": "hierloco.components.gait_policy",
    "TrainedSACLowLevel": "hierloco.components.sac_low_level",
    "TransitionData": "hierloco.components.dynamics_data",
    "UniformActionPolicy": "hierloco.components.dynamics_data",
    "action_motion": "hierloco.components.expert_library",
    "apply_delta": "hierloco.components.com_model",
    "build_expert_library": "hierloco.components.expert_library",
    "check_gait_policy": "hierloco.components.evaluation",
    "collect_transitions": "hierloco.components.dynamics_data",
    "com_model_module": "hierloco.components.com_model",
    "holdout_split": "hierloco.components.com_model",
    "continuity_statistics": "hierloco.components.evaluation",
    "latent_continuity": "hierloco.components.evaluation",
    "latent_grid": "hierloco.components.evaluation",
    "latent_grid_paths": "hierloco.components.evaluation",
    "local_transition": "hierloco.components.com_model",
    "run_closed_loop": "hierloco.components.experts",
    "run_task": "hierloco.components.evaluation",
    "train_com_model": "hierloco.components.com_model",
    "train_gait_policy": "hierloco.components.gait_policy",
    "train_sac": "hierloco.components.sac",
    "train_sac_low_level": "hierloco.components.sac_low_level",
}


__getattr__, __dir__ = lazy_names(__name__, _WHERE, globals())

__all__ = sorted(_WHERE)

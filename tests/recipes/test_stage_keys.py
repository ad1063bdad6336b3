"""Cache keys are complete: every config value that changes an artifact is in the key of the stages it changes (and
of everything downstream), and nothing else is.

The plan of stages of every method that hierloco ships (read from the registry,
:data:`hierloco.pipeline.methods.METHODS`: a new recipe folder is checked with nothing listed here) is computed for its
tiny config, then for the config with one value changed; the set of stages whose key changed is compared with what
must rebuild. (A changed key refuses a training stage and gives an evaluation a new cached file;
``test_lat_recipe.py`` checks both end to end.)
"""

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf, open_dict

from hierloco.pipeline.config import prepare
from hierloco.pipeline.methods import METHODS

RECIPES = [name for name in METHODS.names() if METHODS[name].package.startswith("hierloco.recipes.")]
# what changes no artifact: where results go, how they are shown, how fast they are computed
NOT_IN_KEYS = ("run_dir", "progress", "nthread", "preset_name", "logger.", "eval.figures", "eval.videos",
               "checks.")  # checks stop a run; they change no artifact


CONFIGS: dict = {}


def config(recipe: str):
    """The recipe's tiny config (a fresh copy)."""
    if recipe not in CONFIGS:
        with initialize_config_dir(config_dir=str(METHODS[recipe].folder), version_base=None):
            CONFIGS[recipe] = compose(config_name="config", overrides=["preset=tiny"])
    return CONFIGS[recipe].copy()


def plan_digests(recipe: str, cfg) -> dict[str, str]:
    utils = METHODS[recipe].utils()
    robot = prepare(cfg, utils.checks)
    return {stage.name: stage.digest for stage in utils.plan(cfg, robot)}


def leaves(node, prefix=""):
    for key, value in node.items():
        if OmegaConf.is_dict(value):
            yield from leaves(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


NO_OTHER_VALUE = {("lib", "planner.name"), ("sac", "settings"), ("sac_sac", "settings")}  # one planner, one setting
SPECIAL = {"steps_per_action": 200, "policy.latent_dim": 3, "planner.name": "cem", "robot": "daisy",
           "settings": ["legs_disabled"], "device": None, "planner.top_k": 20,
           "sac.gamma": 0.9, "dynamics.holdout": 0.2, "low_level_actor": "deterministic"}


def changed_value(key: str, value):
    """A valid different value for ``key``, or ``None`` when there is none to try here."""
    if key in SPECIAL:
        return SPECIAL[key]
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value * 1.5
    if OmegaConf.is_list(value) and key.endswith("velocities"):
        return [[0.5 * v for v in pair] for pair in OmegaConf.to_container(value)]
    return None  # strings naming a task type, ...


def changed_stages(recipe: str, key: str, value) -> set[str]:
    other = config(recipe)
    with open_dict(other):
        OmegaConf.update(other, key, value, merge=False)
    a, b = plan_digests(recipe, config(recipe)), plan_digests(recipe, other)
    return {name for name in a.keys() | b.keys() if a.get(name) != b.get(name)}


@pytest.mark.parametrize("recipe", RECIPES)
def test_every_config_value_is_in_a_key_or_changes_nothing(recipe):
    checked = 0
    for key, value in leaves(config(recipe)):
        new = changed_value(key, value)
        if new is None or (recipe, key) in NO_OTHER_VALUE:
            continue
        changed = changed_stages(recipe, key, new)
        if key.startswith(NOT_IN_KEYS):
            assert not changed, f"{recipe}: {key} changes no artifact but changed the keys of {sorted(changed)}"
        else:
            assert changed, f"{recipe}: changing {key} ({value!r} -> {new!r}) changed no stage's key"
        checked += 1
    assert checked >= 20


def test_the_right_stages_change():
    evaluations = {f"evaluation_normal_{t}" for t in ("velocity_tracking", "goal_reaching", "trajectory_tracking",
                                                        "goal_reaching_1p5m", "goal_reaching_3m",
                                                        "velocity_tracking_diagonal")}
    everything = {"experts", "gait_policy", "gait_policy_check", "dynamics_data_normal", "dynamics_model_normal",
                  *evaluations}
    assert changed_stages("lat", "seed", 1) == everything
    assert changed_stages("lat", "policy.epochs", 21) == everything - {"experts"}
    assert changed_stages("lat", "dynamics.lr", 2e-3) == {"dynamics_model_normal", *evaluations}
    assert changed_stages("lat", "dynamics.num_robots", 21) == {"dynamics_data_normal", "dynamics_model_normal",
                                                                 *evaluations}
    assert changed_stages("lat", "planner.num_candidates", 600) == evaluations
    assert changed_stages("lat", "eval.tasks.goal_reaching.num_steps", 5) == {"evaluation_normal_goal_reaching"}
    # the IK key once omitted the seed: a seed-1 run reused a seed-0 run's every stage
    ik = {"dynamics_data_normal", "dynamics_model_normal", *evaluations}
    assert changed_stages("ik", "seed", 1) == ik
    assert changed_stages("ik", "steps_per_action", 200) == ik
    assert changed_stages("lib", "experts.num_experts", 5) == {"experts", *ik}
    sac = changed_stages("sac", "sac.lr", 2e-3)
    assert sac == {f"sac_{t}" for t in ("velocity_tracking", "goal_reaching", "trajectory_tracking")} | evaluations


def test_the_robot_s_fingerprint_is_in_every_key():
    """A user robot edited under the same name, or registered under a built-in's name, is another robot."""
    from hierloco.envs.robots import get_robot, robot_fingerprint

    a1 = get_robot("a1")
    softer = a1.replace(kp=tuple(0.5 * k for k in (a1.kp or [100.0] * a1.num_joints)))
    assert softer.name == "a1" and robot_fingerprint(softer) != robot_fingerprint(a1)
    assert robot_fingerprint(a1.replace(gait_period=0.25)) != robot_fingerprint(a1)


def test_the_hardware_settings_keys():
    """``hardware`` re-learns the CoM model on the perturbed robot, with its options in the key; ``hardware_unadapted``
    evaluates the perturbed robot with the normal setting's model, which it learns even when normal is not asked."""
    cfg = config("lat")
    with open_dict(cfg):
        cfg.settings = ["hardware_unadapted", "hardware"]
    utils = METHODS["lat"].utils()
    plan = {stage.name: stage for stage in utils.plan(cfg, prepare(cfg, utils.checks))}
    assert "dynamics_model_normal" in plan and "evaluation_normal_goal_reaching" not in plan
    assert not any(name.startswith("dynamics_data_hardware_unadapted") for name in plan)
    unadapted = plan["evaluation_hardware_unadapted_goal_reaching"]
    assert unadapted.after["model"] == plan["dynamics_model_normal"].digest
    assert plan["evaluation_hardware_goal_reaching"].after["model"] == plan["dynamics_model_hardware"].digest
    assert plan["dynamics_data_hardware"].params["hardware"]["servo_latency"] == 0.02
    assert "hardware" not in plan["dynamics_data_normal"].params  # nominal keys are as they were
    with open_dict(cfg):
        cfg.hardware = {"servo_latency": 0.04}
    later = {stage.name: stage for stage in utils.plan(cfg, prepare(cfg, utils.checks))}
    changed = {name for name, stage in later.items() if stage.digest != plan[name].digest}
    assert changed == {"dynamics_data_hardware", "dynamics_model_hardware"} | {
        name for name in plan if name.startswith("evaluation_hardware")}


def test_the_hardware_robot_s_own_world_changes_only_its_keys():
    """``hardware_world.*`` puts the perturbed robot (its dynamics data and the evaluations of both hardware
    settings) on a terrain with randomised dynamics; the nominal robot's stages keep their keys, and a run without
    a hardware setting refuses the option (test_user_errors)."""
    from tests.recipes.stage_plans import plan

    settings = "settings=[normal,hardware_unadapted,hardware]"
    before = plan("lat", settings)
    after = plan("lat", settings, "+hardware_world.terrain={name: rough, difficulty: 0.5}",
                 "+hardware_world.randomization=standard")
    changed = {name for name in before if before[name].digest != after[name].digest}
    assert changed == {"dynamics_data_hardware", "dynamics_model_hardware"} | {
        name for name in before if name.startswith("evaluation_hardware")}
    data = after["dynamics_data_hardware"].params
    assert data["terrain"] == {"name": "rough", "difficulty": 0.5, "seed": 0} and data["randomization"]["friction"]
    assert "terrain" not in after["dynamics_data_normal"].params
    assert after["evaluation_hardware_unadapted_goal_reaching"].params["terrain"]["name"] == "rough"
    assert "terrain" not in after["evaluation_normal_goal_reaching"].params
    # the perturbed robot's own world comes last: it wins over the evaluations' world, for its settings only
    over = plan("lat", settings, "eval.terrain=slope", "+hardware_world.terrain=stairs")
    assert over["evaluation_normal_goal_reaching"].params["terrain"]["name"] == "slope"
    assert over["evaluation_hardware_goal_reaching"].params["terrain"]["name"] == "stairs"

"""Typical user mistakes: each is one line on stderr, exit status 2, no traceback, nothing written."""

import contextlib
import io
import runpy
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

MISTAKES = [
    ("robot=spot", "unknown robot 'spot'"),
    ("seed=-1", "seed must be an integer >= 0"),
    ("seed=1.5", "seed must be an integer >= 0"),
    ("settings=[]", "settings is empty"),
    ("settings=[normal,normal]", "lists a setting twice"),
    ("settings=norml", "unknown setting 'norml'"),
    ("+eval.tasks.goal_reaching.radus=2", "unknown option 'radus'; valid options: radius"),
    ("+eval.tasks.velocity_tracking.velocities=fast", "eval task 'velocity_tracking'"),
    ("eval.tasks.goal_reaching.radius=nan", "radius must be a finite number, got nan"),
    ("dynamics.num_transitions=5", "dynamics.num_transitions must be an integer >= 10"),
    ("planner.name=magic", "unknown planner 'magic'"),
    ("policy.latent_dim=7", "policy.latent_dim must be 2, 3 or 4"),
    ("logger.backends=[slack]", "unknown logger backend 'slack'"),
    ("eval.videos=[dance]", "eval.videos names 'dance'"),
    ("foo=1", "Could not override 'foo'"),
    ("planner=fancy", "fancy"),
    ("+hardware.servo_latency=0.03", "no setting simulates the hardware robot"),
    ("+eval.tasks.goal_reaching.split=half", "split must be all or train, got 'half'"),
    ("checks.min_expert_reach=0", "checks.min_expert_reach must be a number in (0, 1], got 0"),
    ("+experts.command_low=[0.5,0,0]", "experts: command_low [0.5, 0.0, 0.0] must be at most command_high"),
    ("+experts.command_high=[1,2]", "experts: command_high must be 3 finite numbers"),
    ("checks.min_reproduced_fraction=1.5", "checks.min_reproduced_fraction must be a number in [0, 1], got 1.5"),
    ("eval.latent_continuity={grid: 1}", "eval.latent_continuity.grid must be an integer >= 2, got 1"),
    ("eval.latent_continuity={grid: 7, sizes: 3}", "eval.latent_continuity must be null or a mapping of grid"),
]


def run_in_process(recipe: str, *overrides: str) -> tuple[int, str]:
    """Runs ``recipes/<recipe>/train.py`` in this process (fast: no interpreter start-up); returns the exit status
    and stderr."""
    train = ROOT / "recipes" / recipe / "train.py"
    saved_argv, saved_path = sys.argv, list(sys.path)
    sys.argv = [str(train), *overrides]
    sys.path.insert(0, str(train.parent))
    sys.modules.pop("utils", None)
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            runpy.run_path(str(train), run_name="__main__")
        code = 0
    except SystemExit as exit_:
        code = exit_.code
    finally:
        sys.argv, sys.path[:] = saved_argv, saved_path
        sys.modules.pop("utils", None)
    return code, err.getvalue()


@pytest.mark.parametrize("overrides, message", [
    (["+hardware.latency=0.03"], "hardware: unknown hardware option(s) ['latency']"),
    (["+hardware.mass_scale=-1"], "hardware: robot 'a1_hardware': mass_scale must be a finite positive number"),
    (["+hardware_world.ground=rough"], "hardware_world: unknown option(s) 'ground'"),
    (["+hardware_world.terrain={name: rough, difficulty: 2}"], "hardware_world.terrain 'rough': difficulty"),
])
def test_a_bad_hardware_option_is_one_clear_line(tmp_path, monkeypatch, overrides, message):
    """The perturbation's options and the perturbed robot's world (``hardware_world``)."""
    monkeypatch.chdir(tmp_path)
    code, stderr = run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'run'}", "settings=[normal,hardware]",
                                  *overrides)
    assert code == 2 and stderr.startswith("error: ") and message in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1 and not (tmp_path / "run").exists()


@pytest.mark.parametrize("override, message", MISTAKES)
def test_a_mistake_is_one_clear_line(tmp_path, monkeypatch, override, message):
    monkeypatch.chdir(tmp_path)
    code, stderr = run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'run'}", override)
    assert code == 2, stderr
    assert stderr.startswith("error: ") and message in stderr, stderr
    assert len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr, stderr
    assert list(tmp_path.iterdir()) == [], "a refused run writes nothing (no run dir, no logs, no outputs/)"


@pytest.mark.parametrize("recipe", ["lib", "ik", "sac"])
def test_every_recipe_reports_mistakes_the_same_way(tmp_path, monkeypatch, recipe):
    monkeypatch.chdir(tmp_path)
    code, stderr = run_in_process(recipe, "preset=tiny", f"run_dir={tmp_path / 'run'}", "seed=-3")
    assert code == 2 and stderr.strip() == "error: bad config: seed must be an integer >= 0, got -3"
    assert not list(tmp_path.iterdir())


def test_a_list_option_given_a_scalar_is_a_one_item_list():
    from omegaconf import OmegaConf

    from hierloco.pipeline.config import as_lists

    cfg = OmegaConf.create({"settings": "normal", "eval": {"videos": None}, "logger": {"backends": ["csv"]}})
    as_lists(cfg, ("settings", "eval.videos", "logger.backends"))
    assert cfg.settings == ["normal"] and cfg.eval.videos is None and cfg.logger.backends == ["csv"]


def test_lib_and_sac_own_checks(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, stderr = run_in_process("lib", "preset=tiny", "planner=random_shooting")
    assert code == 2 and "unknown planner 'random_shooting'" in stderr
    code, stderr = run_in_process("sac", "preset=tiny", "settings=[normal,legs_disabled]")
    assert code == 2 and "normal setting only" in stderr
    code, stderr = run_in_process("ik", "preset=tiny", "+controller.gain=3")
    assert code == 2 and "controller has no option 'gain'" in stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("overrides, message", [
    (("dynamics.model=gp",), "unknown dynamics model 'gp' (dynamics.model: choose from ensemble, mlp)"),
    (("dynamics.model=ensemble", "+dynamics.members=many"), "option members='many' should be like its default 5"),
    (("+dynamics.memberz=3",), "dynamics_model 'mlp' has no option 'memberz' (its options: hidden)"),
    (("planner.risk=mean_std",), "planner.risk=mean_std weighs the disagreement of a model's members: it needs "
                                 "dynamics.model=ensemble"),
    (("planner.risk=cautious",), "unknown risk 'cautious'"),
])
def test_model_and_risk_mistakes_are_one_line(tmp_path, monkeypatch, overrides, message):
    monkeypatch.chdir(tmp_path)
    code, stderr = run_in_process("lat", "preset=tiny", f"run_dir={tmp_path / 'run'}", *overrides)
    assert code == 2 and stderr.startswith("error: ") and message in stderr and len(stderr.splitlines()) == 1, stderr
    assert not (tmp_path / "run").exists()

"""IK end to end (Li et al., RA-L 2021, Sec. IV-C): a CoM dynamics model over velocity commands executed by the
expert controller (Raibert footsteps + leg IK, closed loop), then MPC over the commands.

    python recipes/ik/train.py                       # paper scale, A1, seed 0
    python recipes/ik/train.py preset=small robot=daisy settings=[normal,legs_disabled]
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
from recipes.common.entry import recipe_main
from recipes.common.run import open_run
from utils import METHOD, checks, make_low_level, manifest, plan


@recipe_main(__file__)
def main(cfg) -> float:
    run = open_run(cfg, METHOD, plan, checks, manifest)  # config, every stage's key, lock: before any work

    low_level = make_low_level(run)                                 # command -> expert controller, closed loop

    for setting in run.dynamics_settings:
        data = run.stage(f"dynamics_data_{setting}", low_level)     # random commands chained (Sec. III-C)
        model = run.stage(f"dynamics_model_{setting}", data, low_level(1))  # (dx, dy, dyaw, v') = f(v, command)
        run.evaluate(setting, low_level, model)                     # MPC over the command box

    return run.finish()


if __name__ == "__main__":
    main()

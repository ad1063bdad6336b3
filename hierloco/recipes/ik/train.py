"""IK end to end (Li et al., RA-L 2021, Sec. IV-C): a CoM dynamics model over velocity commands executed by the
expert controller (Raibert footsteps + leg IK, closed loop), then MPC over the commands.

    hierloco train ik                       # paper scale, A1, seed 0
    hierloco train ik preset=small robot=daisy settings=[normal,legs_disabled]
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline import recipe_main
from hierloco.recipes.ik import utils
from hierloco.recipes.ik.utils import make_low_level


@recipe_main(utils)  # config checked, every stage planned and its key checked, run directory locked: before any work
def main(run) -> float:
    plan = run.plan

    low_level = make_low_level(run)                               # command -> expert controller, closed loop

    for setting in plan.settings:
        data = run.stage(setting.data, low_level)                 # random commands chained (Sec. III-C)
        model = run.stage(setting.model, data, low_level(1))      # (dx, dy, dyaw, v') = f(v, command)
        run.evaluate(setting.evaluations, low_level, model)       # MPC over the command box

    return run.finish()


if __name__ == "__main__":
    main()

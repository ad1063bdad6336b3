"""LIB end to end (Li et al., RA-L 2021, Sec. IV-B): the G experts as a discrete action set, a CoM dynamics model
over the expert index, exhaustive MPC over the experts.

    hierloco train lib                       # paper scale, A1, seed 0
    hierloco train lib preset=small robot=daisy
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline import recipe_main
from hierloco.recipes.lib import utils
from hierloco.recipes.lib.utils import make_low_level


@recipe_main(utils)  # config checked, every stage planned and its key checked, run directory locked: before any work
def main(run) -> float:
    plan = run.plan

    library = run.stage(plan.experts)                             # G expert gaits (Sec. III-A)
    low_level = make_low_level(library)                           # action g: replay expert g

    for setting in plan.settings:
        data = run.stage(setting.data, low_level)                 # random experts chained (III-C)
        model = run.stage(setting.model, data, low_level(1))      # over one-hot expert indices
        run.evaluate(setting.evaluations, low_level, model)       # exhaustive MPC over the G experts

    return run.finish()


if __name__ == "__main__":
    main()

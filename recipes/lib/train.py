"""LIB end to end (Li et al., RA-L 2021, Sec. IV-B): the G experts as a discrete action set, a CoM dynamics model
over the expert index, exhaustive MPC over the experts.

    python recipes/lib/train.py                       # paper scale, A1, seed 0
    python recipes/lib/train.py preset=small robot=daisy
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
from recipes.common.entry import recipe_main
from recipes.common.run import open_run
from utils import METHOD, checks, make_low_level, manifest, plan


@recipe_main(__file__)
def main(cfg) -> float:
    run = open_run(cfg, METHOD, plan, checks, manifest)  # config, every stage's key, lock: before any work

    library = run.stage("experts")                                  # G expert gaits (Sec. III-A)
    low_level = make_low_level(library)                             # action g: replay expert g

    for setting in run.dynamics_settings:
        data = run.stage(f"dynamics_data_{setting}", low_level)     # random experts chained (III-C)
        model = run.stage(f"dynamics_model_{setting}", data, low_level(1))  # over one-hot expert indices
        run.evaluate(setting, low_level, model)                     # exhaustive MPC over the G experts

    return run.finish()


if __name__ == "__main__":
    main()

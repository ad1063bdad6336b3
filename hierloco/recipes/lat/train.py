"""LAT end to end (Li et al., RA-L 2021): experts -> latent gait policy -> CoM dynamics -> MPC over z.

    hierloco train lat                       # paper scale, A1, seed 0
    hierloco train lat preset=small robot=daisy settings=[normal,legs_disabled]
    hierloco train lat -m seed=0,1,2         # a sweep (Hydra multirun): one run directory per job

Every stage is cached in the run directory with its key: a re-run reuses finished stages, a killed run resumes.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline import recipe_main
from hierloco.recipes.lat import utils
from hierloco.recipes.lat.utils import make_low_level


@recipe_main(utils)  # config checked, every stage planned and its key checked, run directory locked: before any work
def main(run) -> float:
    plan = run.plan

    library = run.stage(plan.experts)                             # G expert gaits (Sec. III-A)
    trained = run.stage(plan.gait_policy, library)                # pi(t, z) and one z per expert (III-B)
    low_level = make_low_level(run, trained)                      # z -> N joint targets, open loop
    run.stage(plan.gait_policy_check, low_level(1), library)      # pi(., z_g) walks like expert g
    if plan.latent_continuity:                                    # optional: CoM motion over a lattice of z (Fig. 4)
        run.stage(plan.latent_continuity, low_level(1))

    for setting in plan.settings:                                 # normal, legs_disabled: the CoM model of each
        data = run.stage(setting.data, low_level)                 # random z held one action each (III-C)
        model = run.stage(setting.model, data, low_level(1))      # (dx, dy, dyaw, v') = f(v, z)
        run.evaluate(setting.evaluations, low_level, model)       # MPC over z on every task (III-D)

    return run.finish(low_level(1))                               # tables, figures, videos; headline cost


if __name__ == "__main__":
    main()

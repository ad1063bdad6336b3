"""SAC baseline (Li et al., RA-L 2021, Sec. IV-B): the LAT low level (experts -> latent gait policy), then per task a
goal-conditioned SAC high level over z, trained on half of the task's targets and tested on all of them.

    hierloco train sac                       # paper scale, A1, seed 0
    hierloco train sac preset=small robot=daisy

The SAC training loop is :func:`hierloco.components.sac.train_sac` (one loop for SAC's high level and SAC-SAC's low
level), run by ``utils.train_high_level`` on the env and agent it builds.
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline import recipe_main
from hierloco.recipes.sac import utils
from hierloco.recipes.sac.utils import make_low_level


@recipe_main(utils)  # config checked, every stage planned and its key checked, run directory locked: before any work
def main(run) -> float:
    plan = run.plan

    library = run.stage(plan.experts)                             # G expert gaits (Sec. III-A)
    trained = run.stage(plan.gait_policy, library)                # pi(t, z) and one z per expert (III-B)
    low_level = make_low_level(run, trained)                      # z -> N joint targets, open loop
    run.stage(plan.gait_policy_check, low_level(1), library)

    for task in plan.tasks:                                       # one SAC high level per task (IV-B)
        agent = run.stage(task.agent, low_level)                  # trained on half of the task's targets
        for evaluation in task.evaluations:                       # tested on all of them, and on the
            run.stage(evaluation, agent, low_level)               # task's generalisation variants

    return run.finish(low_level(1))


if __name__ == "__main__":
    main()

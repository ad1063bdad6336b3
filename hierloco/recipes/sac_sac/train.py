"""SAC-SAC (Li et al., RA-L 2021, Sec. IV-B): a SAC low level at 100 Hz tracking CoM velocity commands, then per task
a goal-conditioned SAC high level over the command, trained on half of the task's targets and tested on all.

    hierloco train sac_sac                       # paper scale, A1, seed 0
    hierloco train sac_sac preset=small robot=daisy
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline import recipe_main
from hierloco.recipes.sac_sac import utils
from hierloco.recipes.sac_sac.utils import make_low_level


@recipe_main(utils)  # config checked, every stage planned and its key checked, run directory locked: before any work
def main(run) -> float:
    plan = run.plan

    trained = run.stage(plan.low_level)                           # SAC at 100 Hz tracks velocity commands
    low_level = make_low_level(run, trained)                      # command -> the SAC policy, closed loop
    run.stage(plan.low_level_tracking, low_level)                 # its tracking error per command

    for task in plan.tasks:                                       # one SAC high level per task, over the command
        agent = run.stage(task.agent, low_level)                  # on half of the task's targets
        for evaluation in task.evaluations:                       # tested on all of them, and on the
            run.stage(evaluation, agent, low_level)               # task's generalisation variants

    return run.finish()


if __name__ == "__main__":
    main()

"""SAC-SAC (Li et al., RA-L 2021, Sec. IV-B): a SAC low level at 100 Hz tracking CoM velocity commands, then per task
a goal-conditioned SAC high level over the command, trained on half of the task's targets and tested on all.

    python recipes/sac_sac/train.py                       # paper scale, A1, seed 0
    python recipes/sac_sac/train.py preset=small robot=daisy
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
from recipes.common.entry import recipe_main
from recipes.common.run import open_run
from utils import METHOD, checks, make_low_level, manifest, plan


@recipe_main(__file__)
def main(cfg) -> float:
    run = open_run(cfg, METHOD, plan, checks, manifest)  # config, every stage's key, lock: before any work

    trained = run.stage("sac_low_level")                             # SAC at 100 Hz tracks velocity commands
    low_level = make_low_level(run, trained)                         # command -> the SAC policy, closed loop
    run.stage("sac_low_level_tracking", low_level)                   # its tracking error per command

    for name in cfg.eval.tasks:                                      # one SAC high level per task, over the command
        agent = run.stage(f"sac_{name}", low_level)                  # on half of the task's targets
        for evaluation in run.dependents(f"sac_{name}"):             # tested on all of them, and on the
            run.stage(evaluation, agent, low_level)                  # task's generalisation variants

    return run.finish()


if __name__ == "__main__":
    main()

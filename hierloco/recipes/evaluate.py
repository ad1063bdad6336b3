"""Evaluate any trained run on more tasks or other planners, training nothing: a Hydra app over the run's own config
(``hierloco/pipeline/evaluate.py``; ``hierloco evaluate --help`` lists what it may change).

    hierloco evaluate run_dir=outputs/lat/paper/a1_seed0 planner=cem \
        '+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}'
    hierloco evaluate -m run_dir=outputs/lat/paper/a1_seed0 planner.num_candidates=1000,2000,4000
"""

import hierloco  # noqa: F401  (first: the rendering backend is chosen before anything loads MuJoCo)
from hierloco.pipeline.evaluate import evaluate_main

if __name__ == "__main__":
    evaluate_main()

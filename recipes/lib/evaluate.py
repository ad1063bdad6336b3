"""Evaluate a trained LIB run on any tasks, never touching a training stage (see ``recipes/common/evaluate.py``).

    python recipes/lib/evaluate.py run_dir=outputs/lib/paper/a1_seed0 \
        '+eval.tasks.goal_reaching_5m={task: goal_reaching, radius: 5}'
"""

import hierloco  # noqa: F401  (first: headless MuJoCo rendering is set before anything loads MuJoCo)
from recipes.common.evaluate import evaluate_main
from train import main

if __name__ == "__main__":
    evaluate_main(main.body)

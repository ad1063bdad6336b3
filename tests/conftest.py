"""Suite-wide set-up."""

import sys

import absl.logging

# absl's log handler keeps the stream it was created with and closes it on ``logging.shutdown`` when that stream is
# no longer ``sys.stderr``. Imported under pytest's capture, that stream is pytest's capture file; a recipe run
# in-process with stderr redirected (tests/recipes/test_user_errors.py) lets Hydra's logging set-up shut the handler
# down, which closed pytest's capture file and lost every later test's output. The process's own stderr is never
# closed by absl.
absl.logging.get_absl_handler().python_handler.stream = sys.__stderr__

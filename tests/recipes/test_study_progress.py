"""The study's progress line: the estimate counts down between job ends and says when it was too short."""

import time

from hierloco.pipeline.studies import _progress


def test_estimate_counts_down_from_the_last_job_end():
    now = time.perf_counter()
    # jobs of 10 min on 2 slots: 2 running (half done) and 2 pending -> 15 min, 3 min ago -> 12 min
    line = _progress(1, 2, 0, 2, now - 900, [600.0], 2, now - 180)
    assert line.startswith("study: 1 done, 2 running, 0 failed, 2 pending; elapsed 15.0 min")
    assert line.endswith("about 12.0 min to go")
    assert _progress(1, 1, 0, 0, now - 900, [60.0], 2, now - 600).endswith("taking longer than estimated")
    assert "to go" not in _progress(0, 2, 0, 2, now - 60, [], 2, now - 60)  # no job has ended yet

"""The errors hierloco reports to its users in one line, apart from bugs.

- :class:`hierloco.io.ArtifactError`: an artifact on disk is missing, corrupted, or not what was asked for.
- :class:`Finding`: a result about the robot and its setting, not a mistake in the code or the command: experts
  that do not walk as commanded, a gait policy that does not reproduce them, a setting in which every random action
  falls, a robot description that cannot stand. The same config fails the same way on any machine, so the pipeline
  records it (``failed.json``) and a study reports the job as not evaluable instead of running it again
  (``docs/pipeline.md``).
"""

from __future__ import annotations


class Finding(Exception):
    """Base class of the findings about a robot and its setting (see the module docstring)."""


__all__ = ["Finding"]

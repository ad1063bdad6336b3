"""A robot description fixture copied with some keys changed, for tests of user robots."""
from __future__ import annotations

from pathlib import Path

import yaml


def changed_copy(source: Path, directory: Path, **changes) -> Path:
    """A copy of the robot YAML ``source`` as ``directory/robot.yaml`` (its MJCF by absolute path), with the keys
    ``changes`` names set (a value of ``None`` removes the key); leg order stays mapping order."""
    content = yaml.safe_load(source.read_text())
    content["mjcf"] = str(source.parent / content["mjcf"])
    for key, value in changes.items():
        if value is None:
            content.pop(key, None)
        else:
            content[key] = value
    path = directory / "robot.yaml"
    path.write_text(yaml.safe_dump(content, sort_keys=False))
    return path

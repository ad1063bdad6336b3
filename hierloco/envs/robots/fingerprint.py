"""Interim robot fingerprint (replaced by the robots branch's ``robot_fingerprint``)."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import mujoco
import numpy as np


_CACHE: dict = {}


def robot_fingerprint(robot) -> str:
    """Hex sha256 of the compiled model (MJB bytes) and every field of the description."""
    if id(robot) in _CACHE and _CACHE[id(robot)][0] is robot:
        return _CACHE[id(robot)][1]
    from hierloco.envs.robots.spec import compile_model

    model = compile_model(robot)
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    fields = {f.name: getattr(robot, f.name) for f in dataclasses.fields(robot) if f.name not in ("build_spec",)}
    text = json.dumps(fields, default=str, sort_keys=True)
    digest = hashlib.sha256(buffer.tobytes() + text.encode()).hexdigest()
    _CACHE[id(robot)] = (robot, digest)
    return digest

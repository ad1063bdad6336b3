"""Which OpenGL backend MuJoCo renders videos with, chosen safely before MuJoCo is imported.

``import hierloco`` calls :func:`choose` first. With ``MUJOCO_GL`` unset it picks EGL (headless, Mesa) when the
EGL library is installed, else ``disable``; a backend that is asked for but missing here (``egl`` or ``osmesa``
without its library, ``glfw`` without a display) is replaced by ``disable``, so the package always imports and runs;
only videos are then off, and a run that asks for one says so in one line (:func:`unavailable`). A value that is no
backend (``MUJOCO_GL=foo``) is reported by :func:`problem`, which the recipes' config check turns into one error
line.

Example:
    >>> choose()  # done by ``import hierloco``
    >>> os.environ["MUJOCO_GL"] in BACKENDS
    True
"""

from __future__ import annotations

import ctypes.util
import os

BACKENDS = ("egl", "osmesa", "glfw", "disable")
_STATE: dict[str, str | None] = {"asked": None, "reason": None}


def _missing(backend: str) -> str | None:
    if backend == "egl" and ctypes.util.find_library("EGL") is None:
        return "MUJOCO_GL=egl but the EGL library is not installed (apt-get install libegl1 libegl-mesa0)"
    if backend == "osmesa" and ctypes.util.find_library("OSMesa") is None:
        return "MUJOCO_GL=osmesa but the OSMesa library is not installed"
    if backend == "glfw" and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "MUJOCO_GL=glfw but there is no display (use MUJOCO_GL=egl on a headless machine)"
    return None


def choose() -> None:
    """Sets ``MUJOCO_GL`` (and ``PYOPENGL_PLATFORM`` for EGL and OSMesa) to a backend that works here."""
    if _STATE["asked"] is not None:
        return
    asked = os.environ.get("MUJOCO_GL")
    _STATE["asked"] = asked or ""
    if asked is None:
        backend = "egl" if ctypes.util.find_library("EGL") is not None else "disable"
        if backend == "disable":
            _STATE["reason"] = "no EGL library here (apt-get install libegl1 libegl-mesa0 for videos)"
    elif asked not in BACKENDS:
        backend = "disable"
        _STATE["reason"] = f"MUJOCO_GL={asked!r} is not a backend ({', '.join(BACKENDS)})"
    else:
        missing = _missing(asked)
        backend = "disable" if missing else asked
        _STATE["reason"] = missing or ("MUJOCO_GL=disable" if asked == "disable" else None)
    os.environ["MUJOCO_GL"] = backend
    if backend in ("egl", "osmesa"):
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    elif os.environ.get("PYOPENGL_PLATFORM") in ("egl", "osmesa"):
        del os.environ["PYOPENGL_PLATFORM"]


def unavailable() -> str | None:
    """Why videos cannot be rendered in this process, or ``None`` when they can (as far as can be told)."""
    choose()
    return _STATE["reason"]


def problem() -> str | None:
    """The one-line problem with the user's ``MUJOCO_GL`` when it names no backend, else ``None``."""
    choose()
    asked = _STATE["asked"]
    if asked and asked not in BACKENDS:
        return f"MUJOCO_GL={asked!r} is not a rendering backend (choose from {', '.join(BACKENDS)})"
    return None


__all__ = ["BACKENDS", "choose", "problem", "unavailable"]

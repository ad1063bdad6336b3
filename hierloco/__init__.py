"""hierloco: hierarchical legged locomotion with learned latent action spaces, on TorchRL and MuJoCo.

Implements Li et al., "Planning in Learned Latent Action Spaces for Generalizable Legged Locomotion", RA-L 2021
(https://arxiv.org/abs/2008.11867).
"""

import os

# Headless rendering through EGL (Mesa) unless the user chose otherwise; must precede dm_control's import.
os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"] in ("egl", "osmesa"):
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

__version__ = "0.1.0"


def load_run(run_dir):
    """The trained parts of a recipe's run directory: see :func:`hierloco.trained.load_run`."""
    from hierloco.trained import load_run as _load_run

    return _load_run(run_dir)


def export(run_dir, out_dir, **options):
    """Writes a trained run's gait policy, CoM model and planner scoring as ONNX and TorchScript for deployment:
    see :func:`hierloco.exporting.export_run`."""
    from hierloco.exporting import export_run

    return export_run(run_dir, out_dir, **options)


__all__ = ["__version__", "export", "load_run"]

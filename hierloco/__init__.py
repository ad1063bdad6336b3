"""hierloco: hierarchical legged locomotion with learned latent action spaces, on TorchRL and MuJoCo.

Implements Li et al., "Planning in Learned Latent Action Spaces for Generalizable Legged Locomotion", RA-L 2021
(https://arxiv.org/abs/2008.11867).
"""

from hierloco import render_backend

# Headless rendering through EGL (Mesa) when it is installed, else none (videos off, everything else runs); chosen
# before anything imports MuJoCo or dm_control (hierloco.render_backend).
render_backend.choose()

__version__ = "0.1.0"


def load_run(run_dir, device: str = "cpu", *, trust_imports=()):
    """The trained parts of a recipe's run directory, their networks on ``device`` (``trust_imports``: the import
    paths its files may name): see :func:`hierloco.trained.load_run`."""
    from hierloco.trained import load_run as _load_run

    return _load_run(run_dir, device=device, trust_imports=trust_imports)


def export(run_dir, out_dir, **options):
    """Writes a trained run's gait policy, CoM model and planner scoring as ONNX and TorchScript for deployment:
    see :func:`hierloco.exporting.export_run`."""
    from hierloco.exporting import export_run

    return export_run(run_dir, out_dir, **options)


__all__ = ["__version__", "export", "load_run"]

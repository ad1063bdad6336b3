"""Factories of the LAT recipe: the latent low level (``recipes/common/latent.py``) and the config checks.

Everything after the low level (dynamics data, model, MPC, results) is the shared pipeline in
``recipes/common/pipeline.py``. Only recipe code reads the config; the library takes keyword arguments.
"""

from __future__ import annotations

from common import latent, pipeline

METHOD = "lat"
prepare = latent.prepare  # the pipeline's low-level hook: experts -> latent gait policy -> its check


def validate(cfg) -> None:
    extra = pipeline.check_positive({"experts.num_experts": cfg.experts.num_experts, "policy.epochs": cfg.policy.epochs,
                                     "policy.hidden": cfg.policy.hidden})
    if not 1 <= cfg.policy.latent_dim <= 4:
        extra.append(f"policy.latent_dim must be 2, 3 or 4 (1 also works), got {cfg.policy.latent_dim}")
    pipeline.validate(cfg, extra=extra)

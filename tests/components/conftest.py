"""Fixtures the component tests share: A1's experts and a latent gait policy learned from them."""

import pytest


@pytest.fixture(scope="module")
def library():
    """Four A1 experts (seed 0)."""
    from hierloco.components.expert_library import build_expert_library

    return build_expert_library("a1", 4, seed=0, progress=False)


@pytest.fixture(scope="module")
def latent(library):
    """LAT's low level on A1 from :func:`library`: a 2-D latent gait policy, 5 gait periods per action."""
    from hierloco.components.gait_policy import train_gait_policy
    from hierloco.components.low_level import LatentLowLevel

    trained = train_gait_policy(library.joint_targets, latent_dim=2, periods_per_action=5, hidden=64, epochs=20,
                                progress=False)
    return LatentLowLevel(trained, "a1")

"""Figures of :mod:`hierloco.plots` that draw measured geometry."""

import numpy as np

from hierloco.plots import _rounded_box, plot_navigation


def test_an_inflated_box_is_drawn_at_the_inflation_from_the_box_everywhere():
    """The dotted region around a box is what the path planner keeps clear (points within the inflation of the
    box, ``hierloco.envs.navigation.plan_path``): every outline point lies at the inflation from the box, corners
    included (a grown rectangle would put its corners 41 % further out)."""
    half = np.array([0.4, 0.15])
    outline = _rounded_box(*half, 0.65)
    distance = np.linalg.norm(np.maximum(np.abs(outline) - half, 0.0), axis=-1)
    assert np.allclose(distance, 0.65)
    assert np.allclose(outline.max(0), half + 0.65) and np.allclose(outline.min(0), -half - 0.65)


def test_the_navigation_figure_draws_an_arena_with_its_paths(tmp_path):
    from hierloco.envs.navigation import cluttered_arena, plan_path

    arena = cluttered_arena(0)
    planned = plan_path(arena, inflation=0.35)
    plot_navigation(arena, planned, [planned[:, :2] + 0.01], tmp_path / "arena.png", inflation=0.35,
                    labels=["CoM"])
    assert (tmp_path / "arena.png").stat().st_size > 10_000

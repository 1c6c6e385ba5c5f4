"""The demo's planned swing-up: planned from the energy-shaping demo's hanging start, tracked
by the time-varying LQR with the rig's noise, animated and plotted against its plan."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image as PILImage

from equilibrist import get_system
from equilibrist.apps import planned_demo
from equilibrist.control.tvlqr import plan_samples
from equilibrist.errors import DesignError
from equilibrist.tasks import get_task


@pytest.fixture(scope="module")
def cart():
    return get_system("cartpole")


@pytest.fixture(scope="module")
def planned(cart):
    """The cart-pole's plan, tracked run and energy-shaping run (made once: a few seconds)."""
    return planned_demo.planned_run(cart)


def test_the_cart_pole_is_planned_tracked_to_balance_and_drawn(cart, planned, tmp_path,
                                                               monkeypatch):
    monkeypatch.setattr(planned_demo, "planned_run", lambda system, duration=None, energy=None: planned)
    notes: list[str] = []
    images = planned_demo.planned_images(cart, tmp_path, "cart-pole", notes, width=160,
                                         height=120, fps=5.0, max_frames=8)
    assert notes == []
    assert [i.path for i in images] == ["cart-pole/planned_swingup.gif",
                                        "cart-pole/planned_swingup.png"]
    gif, png = tmp_path / "planned_swingup.gif", tmp_path / "planned_swingup.png"
    with PILImage.open(gif) as im:
        assert im.size == (160, 120) and getattr(im, "n_frames", 1) > 1
    with PILImage.open(png) as im:
        assert im.size[0] > 400
    caption = images[0].caption
    assert "4 s planned" in caption and "within 70 % of its track" in caption
    assert "IPOPT solved it in" in caption and "energy-shaping swing-up from the same start" in caption
    assert "balanced from" in caption


def test_the_tracked_run_ends_balanced_on_its_track_from_the_energy_demos_start(cart, planned):
    pr = planned
    task = get_task(cart, "swingup")
    start = task.draw_initial(np.random.default_rng(planned_demo.SEED))
    np.testing.assert_allclose(pr.trajectory.states[0], start, atol=1e-12)
    np.testing.assert_array_equal(pr.tracked.states[0], start)
    np.testing.assert_array_equal(pr.energy.states[0], start)
    assert pr.trajectory.converged and pr.trajectory.duration == 4.0
    assert not pr.tracked.fell and pr.balanced_at is not None
    assert pr.balanced_at < pr.trajectory.duration + 1.0
    assert np.max(np.abs(pr.tracked.state("x"))) < 1.0  # on its track
    # The plan as the tracker samples it: from the start to upright, within 70 % of the track.
    t, xs, us = plan_samples(pr.controller)
    assert t[-1] == pytest.approx(4.0) and xs.shape == (t.size, 4) and us.shape == (t.size, 1)
    np.testing.assert_allclose(xs[0], start, atol=1e-9)
    np.testing.assert_allclose(xs[-1], task.x_op, atol=1e-6)
    # The transcription bounds the knots (and midpoints); the cubic between them may pass
    # the bound by a hair where it is active.
    assert np.max(np.abs(pr.trajectory.states[:, 0])) <= 0.7 + 1e-6
    assert np.max(np.abs(xs[:, 0])) <= 0.7 * 1.01


def test_without_a_plan_the_section_gets_a_note(cart, tmp_path, monkeypatch):
    from equilibrist.control import trajopt

    def refuse(*args, **kwargs):
        raise DesignError("trajectory optimization needs CasADi with IPOPT: pip install "
                          "'equilibrist[trajopt]'")

    monkeypatch.setattr(trajopt, "plan", refuse)
    notes: list[str] = []
    assert planned_demo.planned_images(cart, tmp_path, "cart-pole", notes, width=160,
                                       height=120, fps=5.0, max_frames=8) == []
    assert len(notes) == 1 and "No planned swing-up" in notes[0] and "CasADi" in notes[0]
    assert not (tmp_path / "planned_swingup.gif").exists()
    # A system the demo does not plan for gets nothing, and no note.
    assert planned_demo.planned_images(get_system("seesaw"), tmp_path, "seesaw", notes,
                                       width=160, height=120, fps=5.0) == []
    assert len(notes) == 1

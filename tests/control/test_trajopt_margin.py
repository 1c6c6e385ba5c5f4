"""A plan leaves its tracker room: ``trajopt``'s --margin keeps the cart-pole's plan inside a
share of its track (equilibrist.tasks.planning_bounds)."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.numeric.lookup import get_system
from equilibrist.tasks import get_task, planning_bounds


def test_planning_bounds_shrink_the_region_about_its_centre() -> None:
    task = get_task(get_system("cartpole"), "swingup")
    x_max = task.region["x"][1]
    assert planning_bounds(task) == {"x": pytest.approx((-0.7 * x_max, 0.7 * x_max))}
    assert planning_bounds(task, 0.0) == {"x": pytest.approx(task.region["x"])}
    with pytest.raises(ValueError, match="fraction"):
        planning_bounds(task, 1.0)


def test_the_default_plan_stays_within_seventy_percent_of_the_track(tmp_path) -> None:
    out = tmp_path / "p.npz"
    assert main(["trajopt", "cartpole", "--knots", "40", "--out", str(out)]) == 0
    traj = load_trajectory(out)
    x_max = get_system("cartpole").params["x_max"]
    assert np.abs(traj.states[:, 0]).max() <= 0.7 * x_max + 1e-6
    assert main(["trajopt", "cartpole", "--margin", "1.5"]) == 2

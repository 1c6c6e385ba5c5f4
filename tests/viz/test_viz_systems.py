"""Every plot of every registered system, from real (short) simulations: the
time response, a comparison of two runs and the pole map render to PNG of the
stated pixel size and to SVG that parses with an <svg> root."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image

from equilibrist.control import design
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, simulate
from equilibrist.systems import registry
from equilibrist.viz.plots_maps import plot_poles
from equilibrist.viz.plots_runs import plot_comparison, plot_response

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]

DPI = 40
WIDTH, ROW_HEIGHT = 5.0, 0.8
POLE_W, POLE_H = 4.0, 3.0

# The gyroscope has no input: it spins free from a valid (non-singular) state.
GYRO_START = {"zxz": {"theta": 0.5, "psi_dot": 30.0}, "xyz": {"theta": 0.3, "psi_dot": 30.0}}


def _system(entry):
    spec = entry.spec
    return get_system(spec.name, **({} if spec.variant is None else {spec.variant[0]: spec.variant[1]}))


def _two_runs_and_poles(system):
    """Two short runs (different starts) and what the pole map shows."""
    if system.n_inputs == 0:
        start = GYRO_START[system.spec.variant[1]]
        runs = {
            "nominal": simulate(system, None, duration=0.5, rate=50.0, x0=start),
            "tilted": simulate(system, None, duration=0.5, rate=50.0,
                               x0={**start, "theta": start["theta"] + 0.1}),
        }
        x0 = runs["nominal"].states[0]
        poles = {"linearized at the start": np.linalg.eigvals(system.linearize(x0).A)}
        return runs, poles
    d = design(system, rate=system.spec.control_rate)  # a rate every rig's modes allow
    x_op = np.array(system.operating_point().x, float)
    angle = next((i for i, u in enumerate(system.state_units) if u == "rad"), 0)
    runs = {}
    for label, push in (("small", 0.03), ("larger", 0.06)):
        x0 = x_op.copy()
        x0[angle] += push
        runs[label] = simulate(system, LQG.from_design(d), duration=0.5, x0=x0)
    return runs, d


def _check_png(path, size):
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.format == "PNG"
        assert im.size == size
        im.load()


def _check_svg(path):
    assert ET.parse(path).getroot().tag.endswith("svg")


def _rows(system) -> int:
    """One row per coordinate (its rate beside it) and one per input."""
    return sum(not n.endswith("_dot") for n in system.state_names) + system.n_inputs


@pytest.mark.slow  # compiles each system's simulation core on a fresh machine
@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_every_plot_of_every_system_is_a_valid_image_of_the_stated_size(entry, tmp_path):
    system = _system(entry)
    runs, poles = _two_runs_and_poles(system)
    first = next(iter(runs.values()))

    def size(fig_height: float, fig_width: float = WIDTH) -> tuple[int, int]:
        return round(fig_width * DPI), round(fig_height * DPI)

    for suffix in ("png", "svg"):
        response = tmp_path / f"response.{suffix}"
        fig = plot_response(first, response, width=WIDTH, row_height=ROW_HEIGHT, dpi=DPI)
        if suffix == "png":
            _check_png(response, size(max(2.0, ROW_HEIGHT * _rows(system) + 0.6)))
        else:
            _check_svg(response)

        comparison = tmp_path / f"comparison.{suffix}"
        fig = plot_comparison(runs, comparison, width=WIDTH, row_height=ROW_HEIGHT, dpi=DPI)
        assert [t.get_text() for t in fig.legends[0].get_texts()][:2] == list(runs)
        if suffix == "png":
            _check_png(comparison, size(max(2.0, ROW_HEIGHT * _rows(system) + 0.6)))
        else:
            _check_svg(comparison)

        pole_map = tmp_path / f"poles.{suffix}"
        fig = plot_poles(poles, pole_map, width=POLE_W, height=POLE_H, dpi=DPI)
        discrete = len(fig.axes) == 2  # a sampled design: whole circle and close-up
        if suffix == "png":
            _check_png(pole_map, size(POLE_H, POLE_W * (1.8 if discrete else 1.0)))
        else:
            _check_svg(pole_map)

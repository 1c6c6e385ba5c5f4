"""Plots: every kind renders to PNG and SVG of the stated size, with named axes,
units, limits, references and estimates where the issue asks for them."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image

from equilibrist.control import design
from equilibrist.errors import UnknownNameError
from equilibrist.numeric.lookup import get_system
from equilibrist.viz.output import VizError
from equilibrist.viz.plot_common import display_unit
from equilibrist.viz.plots_maps import plot_poles, plot_region_of_attraction
from equilibrist.viz.plots_runs import plot_comparison, plot_fan, plot_response
from equilibrist.viz.runs import Run


@pytest.fixture(scope="module")
def cartpole():
    return get_system("cartpole")


def make_run(system, *, scale: float = 1.0, fell: bool | None = False, label: str = "run") -> Run:
    t = np.linspace(0.0, 4.0, 201)
    x = np.zeros((201, 4))
    x[:, 0] = 0.2 * scale * np.sin(t)
    x[:, 1] = 0.1 * scale * np.exp(-t) * np.sin(4 * t)
    x[:, 2] = 0.2 * scale * np.cos(t)
    x[:, 3] = 0.1 * scale * np.exp(-t) * (4 * np.cos(4 * t) - np.sin(4 * t))
    command = 260.0 * np.sin(3 * t)[:, None]
    rng = np.random.default_rng(1)
    return Run.from_arrays(
        system, t, x, u=np.clip(command, -200, 200), u_command=command,
        estimate=x + 0.002 * rng.standard_normal(x.shape),
        y=x[:, :2] + 0.001 * rng.standard_normal((201, 2)), output_names=("x", "theta"),
        reference=np.where(t > 2, 0.1, 0.0)[:, None], reference_names=("x",),
        label=label, events=[(2.0, "push")], fell=fell,
    )


def _check_png(path, size):
    with Image.open(path) as im:
        assert im.format == "PNG"
        assert im.size == size


def _check_svg(path):
    root = ET.parse(path).getroot()
    assert root.tag.endswith("svg")


def _labels(fig):
    return [ax.get_ylabel() for ax in fig.axes]


def test_response_plot_names_axes_with_units_and_draws_limits_reference_estimates(cartpole, tmp_path):
    run = make_run(cartpole)
    fig = plot_response(run, tmp_path / "r.png", width=6.0, row_height=1.2, dpi=50)
    _check_png(tmp_path / "r.png", (300, round((1.2 * 3 + 0.6) * 50)))
    plot_response(run, tmp_path / "r.svg", width=6.0, row_height=1.2, dpi=50)
    _check_svg(tmp_path / "r.svg")
    assert _labels(fig) == ["x [m]", "x_dot [m/s]", "theta [deg]", "theta_dot [deg/s]", "F [N]"]
    assert fig.axes[-1].get_xlabel() == "time [s]"
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    for want in ("true", "estimate", "measured", "reference", "applied", "command", "limits", "saturated"):
        assert want in legend
    # The limits are drawn at the input limits.
    ys = {round(float(line.get_ydata()[0]), 6) for line in fig.axes[-1].get_lines()
          if len(set(np.atleast_1d(line.get_ydata()))) == 1}
    assert {-200.0, 200.0} <= ys
    # Angles are shown in degrees: the theta axis holds the data times 180/pi.
    theta_line = next(ln for ln in fig.axes[2].get_lines() if ln.get_label() == "true")
    assert np.allclose(theta_line.get_ydata(), run.state("theta") * 180 / math.pi)
    assert "stayed up" in fig._suptitle.get_text()


def test_response_plot_in_radians_and_for_a_subset(cartpole):
    fig = plot_response(make_run(cartpole), states=["theta"], rates=False, degrees=False)
    assert _labels(fig) == ["theta [rad]", "F [N]"]
    with pytest.raises(UnknownNameError, match="no state 'thetta'"):
        plot_response(make_run(cartpole), states=["thetta"])


def test_comparison_overlays_each_run_with_its_label(cartpole, tmp_path):
    runs = {"LQR": make_run(cartpole), "LQG": make_run(cartpole, scale=0.5)}
    fig = plot_comparison(runs, tmp_path / "c.png", width=5, row_height=1.0, dpi=40)
    _check_png(tmp_path / "c.png", (200, round((1.0 * 3 + 0.6) * 40)))
    plot_comparison(runs, tmp_path / "c.svg")
    _check_svg(tmp_path / "c.svg")
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels[:2] == ["LQR", "LQG"]
    first = fig.axes[0].get_lines()
    assert np.allclose(first[1].get_ydata(), 0.5 * first[0].get_ydata())
    with pytest.raises(VizError, match="no runs"):
        plot_comparison([])
    other = Run.from_arrays(get_system("seesaw"), np.arange(3.0), np.zeros((3, 2)))
    with pytest.raises(VizError, match="their states differ"):
        plot_comparison([make_run(cartpole), other])


def test_fan_plot_draws_median_and_bands_and_counts_falls(cartpole, tmp_path):
    runs = [make_run(cartpole, scale=s, fell=(k == 0)) for k, s in enumerate(np.linspace(0.5, 1.5, 9))]
    fig = plot_fan(runs, tmp_path / "f.png", width=5, row_height=1.0, dpi=40)
    _check_png(tmp_path / "f.png", (200, round((1.0 * 3 + 0.6) * 40)))
    plot_fan(runs, tmp_path / "f.svg")
    _check_svg(tmp_path / "f.svg")
    median = next(ln for ln in fig.axes[0].get_lines() if ln.get_label() == "median")
    assert np.allclose(median.get_ydata(), np.median([r.state("x") for r in runs], axis=0))
    assert "9 runs, 1 fell" in fig._suptitle.get_text()


def test_fan_plot_of_runs_of_different_lengths(cartpole):
    short = make_run(cartpole)
    cut = Run.from_arrays(cartpole, short.t[:50], short.x[:50], u=short.u[:50])
    fig = plot_fan([short, cut])
    median = next(ln for ln in fig.axes[0].get_lines() if ln.get_label() == "median")
    y = median.get_ydata()
    assert np.allclose(y[60:], short.state("x")[60:])  # only the long run after the cut


def test_region_of_attraction_grid_and_scatter(tmp_path):
    th, om = np.meshgrid(np.linspace(-0.4, 0.4, 9), np.linspace(-1, 1, 5))
    ok = np.abs(th + 0.2 * om) < 0.25
    fig = plot_region_of_attraction(th.ravel(), om.ravel(), ok.ravel(), tmp_path / "roa.png",
                                    x_name="theta", y_name="theta_dot", x_unit="rad", y_unit="rad/s",
                                    width=4, height=3, dpi=50)
    _check_png(tmp_path / "roa.png", (200, 150))
    ax = fig.axes[0]
    assert ax.get_xlabel() == "initial theta [deg]"
    assert len(ax.collections) == 1  # a grid of cells
    mesh = ax.collections[0].get_array()
    assert int(np.nansum(mesh)) == int(ok.sum())
    scatter = plot_region_of_attraction([0.1, 0.2, 0.35], [0.0, 0.5, 0.1], [True, True, False],
                                        tmp_path / "s.svg", x_name="a", y_name="b")
    _check_svg(tmp_path / "s.svg")
    assert len(scatter.axes[0].collections) == 2
    with pytest.raises(VizError, match="as many"):
        plot_region_of_attraction([0.1], [0.2, 0.3], [True], x_name="a", y_name="b")


@pytest.mark.parametrize("rate", [None, 100.0])
def test_pole_map_of_a_design(cartpole, tmp_path, rate):
    d = design(cartpole, rate=rate)
    fig = plot_poles(d, tmp_path / "p.png", width=4, height=3, dpi=50)
    _check_png(tmp_path / "p.png", (360 if rate else 200, 150))
    plot_poles(d, tmp_path / "p.svg")
    _check_svg(tmp_path / "p.svg")
    ax = fig.axes[0]
    by_label = {ln.get_label(): ln for ln in ax.get_lines()}
    closed = by_label["state feedback (LQR)"]
    assert np.allclose(np.sort_complex(closed.get_xdata() + 1j * closed.get_ydata()),
                       np.sort_complex(np.asarray(d.poles, complex)))
    assert len(by_label["open loop"].get_xdata()) == 4
    assert ("unit circle (stability limit)" in by_label) == (rate is not None)


def test_pole_map_of_labelled_sets_and_refusals():
    fig = plot_poles({"a": [-1 + 1j, -1 - 1j], "b": [0.5]})
    assert {ln.get_label() for ln in fig.axes[0].get_lines()} >= {"a", "b"}
    with pytest.raises(VizError, match="needs a Design"):
        plot_poles(42)
    with pytest.raises(VizError, match="unsupported format"):
        plot_poles({"a": [-1.0]}, "poles.pdf")


def test_display_units():
    assert display_unit("rad") == (pytest.approx(180 / math.pi), "deg")
    assert display_unit("rad/s")[1] == "deg/s"
    assert display_unit("rad", degrees=False) == (1.0, "rad")
    assert display_unit("m/s") == (1.0, "m/s")


def test_run_from_arrays_checks_shapes(cartpole):
    with pytest.raises(VizError, match=r"x has shape \(3, 2\), expected \(3, 4\)"):
        Run.from_arrays(cartpole, [0, 1, 2], np.zeros((3, 2)))
    with pytest.raises(VizError, match="must increase"):
        Run.from_arrays(cartpole, [0, 2, 1], np.zeros((3, 4)))
    with pytest.raises(VizError, match="'phi' is not a state"):
        Run.from_arrays(cartpole, [0, 1, 2], np.zeros((3, 4)), y=np.zeros((3, 1)), output_names=("phi",))

"""How the objects show in Jupyter: IPython's own display formatter, given the bundles.

Independent truths: the cart-pole's textbook mass matrix, the kinematics every linear
model of it has (``x' = x_dot``), the damping of a sampled pole computed here from
``s = ln(z) / dt``, python-control's phase margin, the PNG and MP4 file signatures.
"""

from __future__ import annotations

import base64
import functools
import io
import re
import types

import control as ct
import numpy as np
import pytest
import sympy
from IPython.core.formatters import DisplayFormatter
from PIL import Image

from equilibrist.control.design import design
from equilibrist.control.design_record import Design
from equilibrist.control.interop import loop_at_input
from equilibrist.notebook.display import register
from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System
from equilibrist.sim import LQG, simulate
from equilibrist.sim.result import SimResult
from equilibrist.viz.animation import animate_inline

PNG = b"\x89PNG\r\n\x1a\n"


@functools.cache
def _cart() -> System:
    return get_system("cartpole")


@functools.cache
def _design(rate: float | None) -> Design:
    return design(_cart(), rate=rate)


@functools.cache
def _run() -> SimResult:
    return simulate(_cart(), LQG.from_design(_design(200.0)), duration=0.5, x0={"theta": 0.1})


@pytest.fixture(scope="module")
def show() -> DisplayFormatter:
    formatter = DisplayFormatter()
    assert register(types.SimpleNamespace(display_formatter=formatter))
    return formatter


def _bundle(formatter: DisplayFormatter, value: object) -> dict[str, str]:
    data, _ = formatter.format(value)
    return data


def _png_size(data: str) -> tuple[int, int]:
    raw = base64.b64decode(data)
    assert raw.startswith(PNG)
    with Image.open(io.BytesIO(raw)) as picture:
        return picture.size


def _cells(table_html: str) -> list[list[str]]:
    rows = re.findall(r"<tr>(.*?)</tr>", table_html)
    return [re.findall(r"<t[hd]>(.*?)</t[hd]>", row) for row in rows]


def test_outside_ipython_or_in_a_terminal_nothing_is_registered() -> None:
    assert not register(types.SimpleNamespace())
    terminal = DisplayFormatter(active_types=["text/plain"])  # what a terminal's IPython shows
    assert not register(types.SimpleNamespace(display_formatter=terminal))
    assert "text/html" not in terminal.format(_design(None))[0]


def test_a_system_shows_its_equations_parameters_and_drawing(show: DisplayFormatter) -> None:
    cart = _cart()
    data = _bundle(show, cart)
    # The textbook cart-pole's mass matrix (pole mass at distance l, inertia I_p about it).
    m_c, m_p, l, I_p, theta = sympy.symbols("m_c m_p l I_p theta")
    M = sympy.Matrix([[m_c + m_p, m_p * l * sympy.cos(theta)],
                      [m_p * l * sympy.cos(theta), I_p + m_p * l**2]])
    assert sympy.latex(M) in data["text/latex"]
    assert r"\ddot{x}" in data["text/latex"] and r"\ddot{\theta}" in data["text/latex"]
    page = data["text/html"]
    assert data["text/latex"] in page
    for parameter in cart.spec.parameters:
        value = cart.params[parameter.name]
        assert f"<code>{parameter.name}</code></th><td>{value:.4g}</td>" in page
    drawing = re.search(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)
    assert drawing is not None and _png_size(drawing.group(1)) == (360, 270)
    assert len(data["text/plain"]) < 200  # not the dataclass's thousands of characters


def test_a_linear_model_names_its_rows_and_columns(show: DisplayFormatter) -> None:
    lin = _cart().linearize()
    page = _bundle(show, lin)["text/html"]
    a_table = page[page.index("<caption style='caption-side:top'>A</caption>"):]
    a_table = a_table[: a_table.index("</table>")]
    cells = _cells(a_table)
    header, rows = cells[0], {row[0]: row[1:] for row in cells[1:]}
    columns = header[1:]
    assert columns == ["x", "theta", "x_dot", "theta_dot"]
    # Kinematics: the position's rate is the velocity state, whatever the physics.
    assert rows["x"][columns.index("x_dot")] == "1"
    assert rows["x"][columns.index("x")] == "0"
    assert rows["theta"][columns.index("theta_dot")] == "1"


def test_a_design_shows_gains_damping_and_margins(show: DisplayFormatter) -> None:
    d = _design(200.0)
    page = _bundle(show, d)["text/html"]
    for z in d.poles:
        s = np.log(complex(z)) * 200.0
        assert f"<td>{-s.real / abs(s):.4g}</td>" in page
    for gain in np.ravel(d.K):
        assert f"<td>{gain:.4g}</td>" in page
    continuous = _design(None)
    _, pm, _, _, _, _ = ct.stability_margins(loop_at_input(continuous))
    assert f"{pm:.4g}° at" in _bundle(show, continuous)["text/html"]
    assert len(repr(d)) < 200


def test_a_compensator_names_its_signals(show: DisplayFormatter) -> None:
    page = _bundle(show, _design(200.0).compensator)["text/html"]
    assert "<th>y_theta</th>" in page and "<th>xhat_theta_dot</th>" in page


def test_a_result_and_a_figure_show_once_as_pictures(show: DisplayFormatter) -> None:
    from equilibrist.viz.plots_runs import plot_response

    data = _bundle(show, _run())
    assert set(data) == {"image/png", "text/plain"}
    width, height = _png_size(data["image/png"])
    assert width > 300 and height > 200
    figure = _bundle(show, plot_response(_run()))
    assert set(figure) == {"image/png", "text/plain"}
    _png_size(figure["image/png"])


def test_a_batch_shows_its_summary_plot(show: DisplayFormatter) -> None:
    from equilibrist.sim import simulate_batch

    batch = simulate_batch(_cart(), LQG.from_design(_design(200.0)), runs=3, duration=0.3,
                           x0={"theta": np.array([0.05, 0.1, 0.15])}, seed=0, record=True)
    _png_size(_bundle(show, batch)["image/png"])


def test_an_animation_plays_inline_as_a_video() -> None:
    shown = animate_inline(_run(), max_frames=5, width=160, height=120, progress=False)
    assert shown.mime == "video/mp4"
    assert shown.data[4:8] == b"ftyp"  # the MP4 file's first box
    page = shown._repr_html_()
    assert page.startswith("<video") and "base64," in page


def test_a_study_shows_its_summary_plot(show: DisplayFormatter, tmp_path) -> None:
    from equilibrist.study import make_study, run_study

    study = make_study("cartpole", vary={"m_p": [0.1, 0.2]}, runs=2, duration=0.2,
                       x0={"theta": [-0.05, 0.05]}, metrics="basic")
    done = run_study(study, tmp_path / "study.parquet")
    width, height = _png_size(_bundle(show, done)["image/png"])
    assert width > 200 and height > 150

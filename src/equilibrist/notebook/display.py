"""How each object a user holds shows in Jupyter: the MIME bundles of systems, linear
models, designs, compensators, results, batches, studies and figures.

:func:`register` tells IPython's display formatter about the types by their module and
name, so that nothing is imported until an object of that type is shown; ``import
equilibrist`` calls it when it runs inside IPython. Each ``*_bundle`` function returns
``{mime type: data}``: HTML for the frontends (Jupyter typesets the ``$$`` LaTeX in it),
a ``text/latex`` equation where there is one, PNG for pictures.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from equilibrist.control.design_record import Design
    from equilibrist.control.lqg import Compensator
    from equilibrist.numeric.linear import LinearModel
    from equilibrist.numeric.system import System
    from equilibrist.sim.batch import MonteCarloResult, RegionOfAttraction
    from equilibrist.sim.batch_result import BatchResult
    from equilibrist.sim.result import SimResult
    from equilibrist.study.runner import StudyRun

Bundle = dict[str, str]

#: Dots per inch of the figures shown inline.
INLINE_DPI = 80.0


# -- small pieces -----------------------------------------------------------------------------
def _number(value: float) -> str:
    if isinstance(value, complex):
        return _complex(value)
    if math.isinf(value):
        return "∞" if value > 0 else "-∞"
    return f"{value:.4g}"


def _complex(value: complex) -> str:
    if abs(value.imag) < 1e-12 * max(1.0, abs(value.real)):
        return _number(value.real)
    sign = "+" if value.imag >= 0 else "-"
    return f"{value.real:.4g} {sign} {abs(value.imag):.4g}j"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], *, caption: str = "") -> str:
    """An HTML table of already escaped cells (the first column is a row header)."""
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join(
        "<tr>" + f"<th>{row[0]}</th>" + "".join(f"<td>{c}</td>" for c in row[1:]) + "</tr>"
        for row in rows
    )
    cap = f"<caption style='caption-side:top'>{caption}</caption>" if caption else ""
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def matrix_table(matrix: np.ndarray, rows: Sequence[str], columns: Sequence[str],
                 *, caption: str = "") -> str:
    """A matrix as an HTML table with its rows and columns named."""
    values = np.atleast_2d(np.asarray(matrix))
    cells = [[html.escape(r), *(_number(v) for v in values[i])] for i, r in enumerate(rows)]
    return _table(["", *(html.escape(c) for c in columns)], cells, caption=caption)


def _png(figure: Figure) -> str:
    """A figure as base64 PNG (the figure is not kept by pyplot, so it shows once)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=INLINE_DPI)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _image(png: str, alt: str) -> str:
    return f"<img src='data:image/png;base64,{png}' alt='{html.escape(alt)}'/>"


def _section(title: str, content: str) -> str:
    return f"<h4 style='margin:0.6em 0 0.2em'>{html.escape(title)}</h4>{content}"


# -- systems ----------------------------------------------------------------------------------
def system_equations(system: System) -> str | None:
    """The equations of motion ``M(q) q'' = F(q, q', u)`` in LaTeX (display math; None for a
    model whose derivation gives no mass matrix)."""
    import sympy

    symbolic = system.symbolic
    if symbolic.M is None or symbolic.F is None:
        return None
    coordinates = system.spec.coordinates
    names: dict[sympy.Symbol, str] = {}
    for symbol in symbolic.M.free_symbols | symbolic.F.free_symbols:
        base = str(symbol).removesuffix("_dot")
        if str(symbol).endswith("_dot") and base in coordinates:
            names[symbol] = rf"\dot{{{sympy.latex(sympy.Symbol(base))}}}"
    accelerations = r" \\ ".join(rf"\ddot{{{sympy.latex(sympy.Symbol(c))}}}" for c in coordinates)
    M = sympy.latex(symbolic.M, symbol_names=names)
    F = sympy.latex(symbolic.F, symbol_names=names)
    return rf"$$ {M} \begin{{bmatrix}} {accelerations} \end{{bmatrix}} = {F} $$"


def system_drawing(system: System) -> str | None:
    """The system drawn at its operating point, as base64 PNG (None: it has no drawing)."""
    import tempfile
    from pathlib import Path

    from equilibrist.viz.frames import draw_state
    from equilibrist.viz.generic import can_draw

    if system.spec.drawing is None and not can_draw(system):  # no scene of its own, no points
        return None
    point = system.operating_point()
    with tempfile.TemporaryDirectory() as folder:
        path = draw_state(system, point.x, Path(folder) / "drawing.png", u=point.u,
                          width=360, height=270)
        return base64.b64encode(path.read_bytes()).decode("ascii")


def system_bundle(system: System) -> Bundle:
    """A system: title and description, states and inputs, parameters, equations, drawing."""
    spec = system.spec
    parameters = [
        [f"<code>{html.escape(p.name)}</code>", _number(float(system.params[p.name])),
         html.escape(p.unit), html.escape(p.meaning)]
        for p in spec.parameters
    ]
    low, high = system.input_limits
    inputs = [
        [f"<code>{html.escape(i.name)}</code>", html.escape(i.unit), html.escape(i.meaning),
         f"[{_number(float(low[k]))}, {_number(float(high[k]))}]"]
        for k, i in enumerate(spec.inputs)
    ]
    states = ", ".join(f"<code>{html.escape(s)}</code>" for s in system.state_names)
    equations = system_equations(system)
    drawing = system_drawing(system)
    parts = [
        f"<h3 style='margin:0.2em 0'>{html.escape(spec.title)} "
        f"<code>{html.escape(system.key)}</code></h3>",
        f"<p>{html.escape(spec.description)}</p>",
        f"<p>States: {states}</p>",
        _section("Equations of motion", f"<div>{equations or 'not a mass-matrix form'}</div>"),
        _section("Parameters", _table(["name", "value", "unit", "meaning"], parameters)),
    ]
    if inputs:
        parts.append(_section("Inputs", _table(["name", "unit", "meaning", "limits"], inputs)))
    if drawing is not None:
        parts.append(_section("At its operating point", _image(drawing, spec.title)))
    bundle = {"text/html": "<div>" + "".join(parts) + "</div>"}
    if equations is not None:
        bundle["text/latex"] = equations
    return bundle


# -- linear models, compensators and designs ---------------------------------------------------
def linear_model_bundle(model: LinearModel) -> Bundle:
    """A linear model: ``A, B, C, D`` with the states', inputs' and outputs' names, and poles."""
    kind = "continuous" if model.dt is None else f"discrete, dt = {model.dt:g} s"
    title = f"Linear model of <code>{html.escape(model.system or '?')}</code> ({kind})"
    x, u, y = model.state_names, model.input_names, model.output_names
    parts = [
        f"<h3 style='margin:0.2em 0'>{title}</h3>",
        "<div style='display:flex;flex-wrap:wrap;gap:1.5em'>",
        matrix_table(model.A, x, x, caption="A"),
        matrix_table(model.B, x, u, caption="B"),
        matrix_table(model.C, y, x, caption="C"),
        matrix_table(model.D, y, u, caption="D"),
        "</div>",
        _section("Poles", ", ".join(_complex(complex(p)) for p in model.poles)),
    ]
    return {"text/html": "".join(parts)}


def compensator_bundle(compensator: Compensator) -> Bundle:
    """A compensator: its matrices with the names of its signals."""
    kind = compensator.form if compensator.dt is None else (
        f"{compensator.form}, dt = {compensator.dt:g} s")
    x, u, y = compensator.state_names, compensator.input_names, compensator.output_names
    parts = [
        f"<h3 style='margin:0.2em 0'>Compensator ({html.escape(kind)})</h3>",
        "<div style='display:flex;flex-wrap:wrap;gap:1.5em'>",
        matrix_table(compensator.A, x, x, caption="A"),
        matrix_table(compensator.B, x, u, caption="B"),
        matrix_table(compensator.C, y, x, caption="C"),
        matrix_table(compensator.D, y, u, caption="D"),
        "</div>",
    ]
    return {"text/html": "".join(parts)}


def _pole_rows(design_poles: Sequence[object]) -> list[list[str]]:
    from equilibrist.control.analysis import PoleInfo

    rows = []
    for info in design_poles:
        assert isinstance(info, PoleInfo)
        rows.append([_complex(info.pole), _number(info.damping), _number(info.natural_frequency),
                     _number(info.time_constant)])
    return rows


def design_bundle(design: Design) -> Bundle:
    """A design: gains, poles with damping, margins, the choices made."""
    kind = "continuous" if design.rate is None else (
        f"discrete at {design.rate:g} Hz ({design.discretization}, {design.kalman_form} filter)"
        + (f", for a loop {design.delay} period(s) late" if design.delay else ""))
    parts = [f"<h3 style='margin:0.2em 0'>LQG design of <code>{html.escape(design.system_key)}"
             f"</code>, {html.escape(kind)}</h3>",
             _section("State feedback u = -K x", matrix_table(
                 design.K, design.input_names, design.model_state_names))]
    if design.Kc is not None:
        parts.append(_section("Reference gain Kc", matrix_table(
            design.Kc, design.input_names, design.tracked)))
    elif design.kc_note:
        parts.append(f"<p>No reference gain: {html.escape(design.kc_note)}</p>")
    header = ["pole", "damping", "ω<sub>n</sub> [rad/s]", "τ [s]"]
    parts.append(_section("Closed-loop poles (state feedback)",
                          _table(header, _pole_rows(design.pole_table))))
    parts.append(_section("Estimator poles", _table(header, _pole_rows(design.estimator_pole_table))))
    for label, margins in (("Margins of the LQG loop at the input", design.margins),
                           ("Margins of the state feedback alone", design.lqr_margins)):
        if margins is None:
            continue
        rows = [["gain", f"{_number(margins.gain_lower)} … {_number(margins.gain_upper)}"],
                ["phase", f"{_number(margins.phase_margin)}° at "
                          f"{_number(margins.gain_crossover)} rad/s"],
                ["min |1 + L|", _number(margins.return_difference)]]
        parts.append(_section(label, _table(["", "margin"], rows)))
    for note in design.notes:
        parts.append(f"<p><em>{html.escape(note)}</em></p>")
    return {"text/html": "".join(parts)}


# -- results and figures --------------------------------------------------------------------
def figure_bundle(figure: Figure) -> Bundle:
    """A figure made without pyplot, as PNG: shown once, inline."""
    return {"image/png": _png(figure)}


def result_bundle(result: SimResult) -> Bundle:
    """A simulation result: its response plot."""
    from equilibrist.viz.plots_runs import plot_response

    return figure_bundle(plot_response(result, dpi=INLINE_DPI))


def batch_bundle(batch: BatchResult | MonteCarloResult | RegionOfAttraction) -> Bundle:
    """A batch (or a Monte-Carlo run, a region of attraction): its summary plot."""
    from equilibrist.viz.plots import plot_batch

    return figure_bundle(plot_batch(batch, dpi=INLINE_DPI))


def study_bundle(run: StudyRun) -> Bundle:
    """A study that ran: its first metric over the quantities it varied (its summary plot)."""
    import tempfile
    from pathlib import Path

    from equilibrist.study.plot import plot_study
    from equilibrist.study.store import read_study

    table, study = read_study(run.out)
    with tempfile.TemporaryDirectory() as folder:
        path = plot_study(table, study, Path(folder) / "study.png", dpi=INLINE_DPI)
        return {"image/png": base64.b64encode(path.read_bytes()).decode("ascii")}


#: What shows each type: (module, class name, the function making its bundle).
FORMATTERS: tuple[tuple[str, str, Callable[..., Bundle]], ...] = (
    ("equilibrist.numeric.system", "System", system_bundle),
    ("equilibrist.numeric.linear", "LinearModel", linear_model_bundle),
    ("equilibrist.control.lqg", "Compensator", compensator_bundle),
    ("equilibrist.control.design_record", "Design", design_bundle),
    ("equilibrist.sim.result", "SimResult", result_bundle),
    ("equilibrist.sim.batch_result", "BatchResult", batch_bundle),
    ("equilibrist.sim.batch", "MonteCarloResult", batch_bundle),
    ("equilibrist.sim.batch", "RegionOfAttraction", batch_bundle),
    ("equilibrist.study.runner", "StudyRun", study_bundle),
    ("matplotlib.figure", "Figure", figure_bundle),
)


def register(shell: object | None = None) -> bool:
    """Register the bundles with IPython's display formatter (*shell*: the running one).

    Returns False outside IPython, and in a terminal's IPython (it shows text only: a
    plot made for each result shown would be thrown away). Types are named by module and
    class, so registering imports none of them.
    """
    if shell is None:
        try:
            from IPython import get_ipython
        except ImportError:
            return False
        shell = get_ipython()
    display = getattr(shell, "display_formatter", None)
    formatter = getattr(display, "mimebundle_formatter", None)
    if formatter is None or "text/html" not in getattr(display, "active_types", ()):
        return False
    for module, name, bundle in FORMATTERS:
        formatter.for_type_by_name(module, name, bundle)
    return True

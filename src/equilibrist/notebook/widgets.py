"""Sliders over a design: the LQR weights and the system's parameters, redesigned and
simulated again on every change.

Each change runs the same two calls a script makes, :func:`~equilibrist.control.design.design`
and :func:`~equilibrist.sim.run.simulate` (the compiled core, built once per system and
reused), so what the sliders show is what the script would get. ipywidgets draws them:
``pip install 'equilibrist[notebook]'``.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from equilibrist.control.design_record import Design
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

#: Decades a weight's slider spans on either side of its starting value.
WEIGHT_DECADES = 2.0
#: Factor a parameter's slider spans on either side of its value (within its range).
PARAMETER_SPAN = 3.0


def _ipywidgets() -> Any:
    try:
        import ipywidgets
    except ImportError as missing:
        raise EquilibristError(
            "sliders need ipywidgets: pip install 'equilibrist[notebook]'"
        ) from missing
    return ipywidgets


class Explorer:
    """A design's weights and a system's parameters as sliders, with the closed loop's run.

    Build it with :func:`explore`. After each change, :attr:`design` and :attr:`result`
    hold the new design and its run (or :attr:`error` says why there is none), and the
    widget shows the design's poles and margins and the run's plot.
    """

    def __init__(self, system: System, *, rate: float | None, duration: float,
                 x0: Mapping[str, float] | None, parameters: Sequence[str], seed: int) -> None:
        from equilibrist.control.design import design

        widgets = _ipywidgets()
        self.system = system
        self.rate = float(system.spec.control_rate if rate is None else rate)
        self.duration = float(duration)
        self.x0 = dict(x0 or {})
        self.seed = seed
        start = design(system, rate=self.rate)
        self.q_sliders = [self._weight_slider(widgets, f"q {name}", start.Q[i, i])
                          for i, name in enumerate(start.state_names)]
        self.r_sliders = [self._weight_slider(widgets, f"r {name}", start.R[i, i])
                          for i, name in enumerate(start.input_names)]
        known = {p.name: p for p in system.spec.parameters}
        unknown = [name for name in parameters if name not in known]
        if unknown:
            raise EquilibristError(
                f"no parameter {', '.join(map(repr, unknown))} in {system.key}: expected one of "
                f"{', '.join(known)}")
        self.parameter_sliders = {}
        for name in parameters:
            value, spec = float(system.params[name]), known[name]
            low = max(spec.low, value / PARAMETER_SPAN) if value > 0 else spec.low
            high = min(spec.high, value * PARAMETER_SPAN) if value > 0 else spec.high
            self.parameter_sliders[name] = widgets.FloatSlider(
                value=value, min=low, max=high, step=(high - low) / 100,
                description=name, continuous_update=False, readout_format=".3g")
        self.summary = widgets.HTML()
        self.output = widgets.Output()
        for slider in self._sliders():
            slider.observe(lambda _change: self.update(), names="value")
        self.widget = widgets.VBox([
            widgets.HBox([widgets.VBox(self.q_sliders + self.r_sliders),
                          widgets.VBox(list(self.parameter_sliders.values()))]),
            self.summary, self.output,
        ])
        self.design: Design | None = None
        self.result: SimResult | None = None
        self.figure: Figure | None = None
        self.error = ""
        self.update()

    @staticmethod
    def _weight_slider(widgets: Any, label: str, value: float) -> Any:
        exponent = math.log10(value)
        return widgets.FloatLogSlider(
            value=value, base=10, min=exponent - WEIGHT_DECADES, max=exponent + WEIGHT_DECADES,
            step=0.05, description=label, continuous_update=False, readout_format=".3g")

    def _sliders(self) -> list[Any]:
        return [*self.q_sliders, *self.r_sliders, *self.parameter_sliders.values()]

    @property
    def q(self) -> np.ndarray:
        """The state weights the sliders hold (the diagonal of ``Q``)."""
        return np.array([float(s.value) for s in self.q_sliders])

    @property
    def r(self) -> np.ndarray:
        """The input weights the sliders hold (the diagonal of ``R``)."""
        return np.array([float(s.value) for s in self.r_sliders])

    @property
    def params(self) -> dict[str, float]:
        """The parameters the sliders hold."""
        return {name: float(s.value) for name, s in self.parameter_sliders.items()}

    def update(self) -> None:
        """Design and simulate with the sliders' values, and show the outcome."""
        from equilibrist.control.design import design
        from equilibrist.sim.controllers import LQG
        from equilibrist.sim.noise import Noise
        from equilibrist.sim.run import simulate
        from equilibrist.viz.plots_runs import plot_response

        try:
            system = self.system.with_params(**self.params)
            made = design(system, q=self.q, r=self.r, rate=self.rate)
            result = simulate(system, LQG.from_design(made), duration=self.duration,
                              x0=self.x0 or None, noise=Noise.from_design(made), seed=self.seed)
        except EquilibristError as problem:
            self.design, self.result, self.figure, self.error = None, None, None, str(problem)
            self.summary.value = f"<p style='color:#b00'>{html.escape(self.error)}</p>"
            self.output.clear_output()
            return
        self.design, self.result, self.error = made, result, ""
        self.figure = plot_response(result, system=system, dpi=80.0)
        self.summary.value = self._summary(made, result)
        self.output.clear_output(wait=True)
        with self.output:
            from IPython.display import display

            display(self.figure)  # type: ignore[no-untyped-call]

    @staticmethod
    def _summary(made: Design, result: SimResult) -> str:
        slowest = max(info.time_constant for info in made.pole_table)
        least = min(info.damping for info in made.pole_table)
        margins = made.margins
        gain = "" if margins is None else (
            f", gain margin {margins.gain_lower:.3g} … {margins.gain_upper:.3g}, "
            f"phase margin {margins.phase_margin:.3g}°")
        outcome = "stayed up" if result.stayed_up else f"fell at {result.fell_at:.3g} s"
        return (f"<p>K = {html.escape(str(np.round(made.K, 3).tolist()))}; slowest pole "
                f"τ = {slowest:.3g} s, least damping {least:.2f}{gain}; the run {outcome}.</p>")

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)  # type: ignore[no-untyped-call]


def explore(system: System, *, rate: float | None = None, duration: float = 3.0,
            x0: Mapping[str, float] | None = None, parameters: Sequence[str] = (),
            seed: int = 0) -> Explorer:
    """Sliders over *system*'s LQG design and run, for a notebook.

    Parameters
    ----------
    system : equilibrist.numeric.system.System
        The system (its parameters as bound are the sliders' starting values).
    rate : float, optional
        The design's and the run's sample rate [Hz] (default the system's control rate).
    duration : float
        Seconds simulated after each change.
    x0 : mapping name -> value, optional
        Initial state components (absolute), as :func:`~equilibrist.sim.run.simulate`'s.
    parameters : sequence of str
        The parameters to put on sliders (each within its range, a factor of 3 around
        its value).
    seed : int
        The noise's seed (process and sensor noise from the design's covariances).

    Returns
    -------
    Explorer
        Shows as the sliders in a notebook; its ``design`` and ``result`` follow them.
    """
    return Explorer(system, rate=rate, duration=duration, x0=x0, parameters=parameters,
                    seed=seed)

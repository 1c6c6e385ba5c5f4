"""Closed-loop simulation: digital controllers, noise, saturation, events, batches.

Layer ``sim`` (it imports from ``numeric`` and ``control``). The core is
C generated per system and controller, compiled by the machine's C compiler and
cached on disk by content (:mod:`equilibrist.sim.kernel`, :mod:`equilibrist.native`); everything here shares it:

* :func:`simulate` -- one run (:class:`SimResult`);
* :func:`simulate_batch` -- many runs at once on all cores (:class:`BatchResult`),
  :func:`region_of_attraction`, :func:`monte_carlo`;
* controllers of the one contract (:mod:`equilibrist.control.controller`):
  :class:`LinearController` and :class:`NonlinearController` run compiled,
  a :class:`PythonController` is called from Python; :class:`OpenLoop`,
  :class:`StateFeedback` and :class:`LQG` describe linear ones; an object
  with the older ``step(t, y, r)`` or a function still runs;
* :class:`Noise`; :class:`Rig` (a rig's effects: torque response, delays, noise,
  encoders, perturbations); events :class:`Kick`, :class:`Pulse`, :class:`Impulse`,
  :class:`ParameterChange`; reference signals :class:`Step`, :class:`Ramp`,
  :class:`Square`, :class:`Samples`;
* :class:`Stepper` -- the plant alone, stepped with a held input.

Importing this package does no work; a core is built or loaded on first use.
"""

from typing import TYPE_CHECKING

from equilibrist._lazy import exports

# Each name from its module on first use (PEP 562): a command that runs one simulation
# does not import the batch machinery (worker pools, result files) it does not need.
_WHERE = {
    "LinearController": "equilibrist.control.linear",
    "NonlinearController": "equilibrist.control.nonlinear",
    "PythonController": "equilibrist.control.python_controller",
    "PythonControllerBase": "equilibrist.control.python_controller",
    "BatchResult": "equilibrist.sim.batch_result",
    "MonteCarloResult": "equilibrist.sim.batch",
    "RegionOfAttraction": "equilibrist.sim.batch",
    "monte_carlo": "equilibrist.sim.batch",
    "region_of_attraction": "equilibrist.sim.batch",
    "simulate_batch": "equilibrist.sim.batch",
    "LQG": "equilibrist.sim.controllers",
    "Controller": "equilibrist.sim.controllers",
    "OpenLoop": "equilibrist.sim.controllers",
    "StateFeedback": "equilibrist.sim.controllers",
    "Impulse": "equilibrist.sim.events",
    "Kick": "equilibrist.sim.events",
    "ParameterChange": "equilibrist.sim.events",
    "Pulse": "equilibrist.sim.events",
    "Noise": "equilibrist.sim.noise",
    "Rig": "equilibrist.sim.rig",
    "SimResult": "equilibrist.sim.result",
    "simulate": "equilibrist.sim.run",
    "Constant": "equilibrist.sim.signals",
    "Ramp": "equilibrist.sim.signals",
    "Samples": "equilibrist.sim.signals",
    "Square": "equilibrist.sim.signals",
    "Step": "equilibrist.sim.signals",
    "Stepper": "equilibrist.sim.stepper",
}

if TYPE_CHECKING:
    from equilibrist.control.linear import LinearController
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.control.python_controller import PythonController, PythonControllerBase
    from equilibrist.sim.batch import (
        MonteCarloResult,
        RegionOfAttraction,
        monte_carlo,
        region_of_attraction,
        simulate_batch,
    )
    from equilibrist.sim.batch_result import BatchResult
    from equilibrist.sim.controllers import LQG, Controller, OpenLoop, StateFeedback
    from equilibrist.sim.events import Impulse, Kick, ParameterChange, Pulse
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.result import SimResult
    from equilibrist.sim.rig import Rig
    from equilibrist.sim.run import simulate
    from equilibrist.sim.signals import Constant, Ramp, Samples, Square, Step
    from equilibrist.sim.stepper import Stepper


__getattr__ = exports(__name__, _WHERE, globals())

__all__ = [
    "LQG",
    "BatchResult",
    "Constant",
    "Controller",
    "Impulse",
    "Kick",
    "LinearController",
    "MonteCarloResult",
    "Noise",
    "NonlinearController",
    "OpenLoop",
    "ParameterChange",
    "Pulse",
    "PythonController",
    "PythonControllerBase",
    "Ramp",
    "RegionOfAttraction",
    "Rig",
    "Samples",
    "SimResult",
    "Square",
    "StateFeedback",
    "Step",
    "Stepper",
    "monte_carlo",
    "region_of_attraction",
    "simulate",
    "simulate_batch",
]

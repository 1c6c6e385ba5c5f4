"""One controller contract, consumed unchanged by the simulator, batches and the C export.

A controller is one of three kinds of value:

:class:`LinearController`
    One discrete state-space form in deviation coordinates about the
    operating point (``dy = y - y_op``, ``dr = r - r_op``,
    ``du = u_applied - u_op``)::

        u  = u_op + Cc z + Dy dy + Dr dr          then saturated (and delayed)
        z+ = Ac z + By dy + Br dr + Bu du          du: the input that acted

    with, for the record, the state estimate ``x_hat = x_op + Ez z + Ey dy``.
    LQR (:meth:`LinearController.state_feedback`), both discrete LQG forms
    (:meth:`LinearController.lqg`), a design (:meth:`LinearController.from_design`)
    and the open loop (:meth:`LinearController.open_loop`) are constructors
    of it. The compiled simulation core runs it through the source
    :data:`LINEAR_SOURCE` (one generic loop), the C export writes the same
    loop once in C plus the matrices, and :meth:`LinearController.output`
    and :meth:`LinearController.update` run that very source in Python.

:class:`NonlinearController`
    Python source translated to C into the system's simulation core
    (as the system's own ``f`` is), defining::

        def output(t, z, y, r, params, u_out): ...            # u_out[:] = command
        def update(t, z, y, r, u_applied, params, z_out): ...  # z_out[:] = next z
        def estimate(t, z, y, r, params, x_out): ...           # only with has_estimate

    ``t`` the sample time [s], ``z`` the controller state (length
    ``n_z``), ``y`` the measured outputs, ``r`` the references (absolute
    units, all 1-D float64 arrays), ``params`` the controller's parameter
    vector. The functions use ``math`` and ``numpy`` only, allocate nothing
    and return nothing; any helper function in the source is compiled too.
    The linear library functions ``linear_output``, ``linear_update`` and
    ``linear_estimate`` (same signatures, *params* a
    :meth:`LinearController.packed` vector) are in scope, so a nonlinear
    controller embeds a linear one by carrying its packed vector inside its
    own parameters (``params[a:b]``) and its state inside its own
    (``z[c:d]``). :func:`supervisor_source` builds the switching logic with
    hysteresis that hands over between two such controllers.

:class:`PythonController`
    A protocol for controllers written in Python: ``reset()``,
    ``output(t, y, r) -> u`` and ``update(t, y, r, u_applied)``, plus the
    attributes ``rate``, ``outputs`` and ``estimate`` (None when there is
    nothing to say). :class:`PythonControllerBase` gives those defaults.
    The simulator calls them once per sample; batches of them run in
    worker processes (the controller must pickle). An object with the old
    ``step(t, y, r)`` method, or a function ``(t, y, r) -> u``, runs
    through :class:`StepAdapter`.

The command line's ``--controller`` choices are a registry of builders
(:func:`equilibrist.controllers.kinds.register_controller`, :func:`equilibrist.controllers.kinds.build_controller`): ``lqr``, ``lqg``
and ``none`` are registered here; a module that registers ``swingup`` or
``mpc`` adds them everywhere at once.
"""

from __future__ import annotations

import types
from typing import Protocol, runtime_checkable

from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import (
    NonlinearController,
)
from equilibrist.control.python_controller import (
    PythonController,
    StepAdapter,
)
from equilibrist.errors import ControllerError

AnyController = LinearController | NonlinearController | PythonController


@runtime_checkable
class DescribedController(Protocol):
    """A controller that describes itself (the linear, nonlinear and MPC controllers)."""

    def describe(self) -> dict[str, object]:
        """Its kind and settings, for ``design`` and reports (JSON-ready)."""
        ...


def describe_controller(ctrl: AnyController, kind: str) -> dict[str, object]:
    """``ctrl.describe()``, or ``{"kind": kind}`` for a controller that does not describe itself."""
    if isinstance(ctrl, DescribedController):
        return ctrl.describe()
    return {"kind": kind}


def measured_outputs(ctrl: AnyController | None) -> tuple[str, ...] | None:
    """The states *ctrl* measures, in the order of its ``y`` (None: the run's outputs)."""
    if ctrl is None:
        return None
    if isinstance(ctrl, LinearController | NonlinearController):
        return ctrl.output_names
    return ctrl.outputs


def python_controller_name(py: PythonController) -> str:
    """The class (or function) name of the controller the user wrote (through the adapter)."""
    target = py.target if isinstance(py, StepAdapter) else py
    if isinstance(target, types.FunctionType | types.MethodType | types.BuiltinFunctionType):
        return target.__name__
    return type(target).__name__


def as_python_controller(obj: object) -> PythonController:
    """*obj* as a :class:`PythonController`: itself, or through :class:`StepAdapter`."""
    if all(callable(getattr(obj, name, None)) for name in ("reset", "output", "update")) and all(
        hasattr(obj, a) for a in ("rate", "outputs", "estimate")
    ):
        return obj  # type: ignore[return-value]
    if (hasattr(obj, "step") and callable(obj.step)) or callable(obj):
        return StepAdapter(obj)
    raise ControllerError(
        f"{type(obj).__name__} is not a controller: expected a LinearController, a "
        "NonlinearController, a PythonController (reset, output, update), an object with "
        "step(t, y, r), or a function (t, y, r) -> u"
    )


__all__ = [
    "AnyController",
    "as_python_controller",
]

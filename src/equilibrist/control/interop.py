"""Conversion to and from python-control's ``StateSpace``.

:func:`to_statespace` carries the names of states, inputs and outputs and
the sample period (python-control writes continuous time as ``dt = 0``),
so that python-control wires a plant and a compensator by name::

    plant = to_statespace(d)                # the plant in the design's timebase
    comp = to_statespace(d.compensator)     # inputs: the plant's outputs, then r_<tracked>
    loop = control.interconnect([plant, comp], inplist=["r_x"], outlist=["x", "theta"])
    loop = control.feedback(plant, comp[:, plant.output_labels], sign=1)  # references at zero

:func:`from_statespace` goes back to a :class:`LinearModel`; the
operating point is not part of a ``StateSpace``, so it is given (default
zero). :func:`loop_at_input` is a design's loop as implemented, broken at
the plant input: the system whose margins the design reports.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import checks
from equilibrist.control.lqg import Compensator
from equilibrist.errors import DesignError
from equilibrist.numeric.linear import LinearModel

if TYPE_CHECKING:
    import control

    from equilibrist.control.design_record import Design

#: The controllers whose loop :func:`loop_at_input` builds from a design.
LOOP_CONTROLLERS = ("lqg", "lqr")


def to_statespace(
    model: LinearModel | Compensator | Design, *, name: str | None = None
) -> control.StateSpace:
    """A named ``control.StateSpace`` of a linear model, a compensator or a design's plant.

    The names are the ones the other side of the loop uses, so that
    ``control.interconnect([to_statespace(d), to_statespace(d.compensator)],
    inplist=[...], outlist=[...])`` closes the loop with no connection written
    by hand: the plant's inputs are the compensator's outputs (``"F"``), the
    plant's outputs (``"x"``, ``"theta"``) the compensator's measurement
    inputs, and both are in the design's timebase.

    Parameters
    ----------
    model:
        A :class:`LinearModel` (continuous or discrete, as it is); a
        :class:`~equilibrist.control.design_record.Design`, for its plant in
        the design's timebase (``d.model``: the sampled plant at the design's
        rate for a discrete design, ``d.plant`` for a continuous one), named
        after the system; or a :class:`~equilibrist.control.lqg.Compensator`
        in its timebase with its own command fed back inside it (the loop the
        simulator and the C export run: the Kalman filter is fed the command
        it computed, ``u = -K xhat``). A compensator's inputs are the measured
        outputs, named as the plant's outputs, then the references
        ``r_<tracked output>``; its outputs the plant's inputs; its states
        ``xhat_<state>``.
    name:
        The system's name in python-control (default: the system key for a
        model or a design, ``"compensator"`` for a compensator).

    Notes
    -----
    A saturated actuator applies less than the command; a linear
    interconnection has no saturation, so there the command is applied.
    """
    import control

    from equilibrist.control.design_record import Design

    if isinstance(model, Design):
        model = model.model
    if isinstance(model, Compensator):
        A, B, C, D = closed_compensator(model)
        inputs = model.measured_names + tuple(f"r_{n}" for n in model.tracked_names)
        return control.ss(
            A,
            B,
            C,
            D,
            0 if model.dt is None else model.dt,
            states=list(model.state_names),
            inputs=list(inputs),
            outputs=list(model.output_names),
            name=name or "compensator",
        )
    if not isinstance(model, LinearModel):
        raise DesignError(
            "to_statespace needs a LinearModel, a Compensator or a Design, got "
            f"{type(model).__name__}"
        )
    return control.ss(
        model.A,
        model.B,
        model.C,
        model.D,
        0 if model.dt is None else model.dt,
        states=list(model.state_names),
        inputs=list(model.input_names),
        outputs=list(model.output_names),
        name=name or model.system or "plant",
    )


def closed_compensator(
    comp: Compensator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The compensator with its command fed back: ``(A, B, C, D)`` from the measurements and
    references ``w`` to the command ``u``.

    The compensator is ``xc+ = A xc + Bu u + Bw w``, ``u = C xc + Du u + Dw w``; with
    ``u`` its own command, ``u = (I - Du)^-1 (C xc + Dw w)`` (``Du`` is zero in every form
    the designs make; the solve keeps the algebra general).
    """
    m = len(comp.plant_input_names)
    close = np.linalg.inv(np.eye(m) - comp.D[:, :m])
    Cu, Dwu = close @ comp.C, close @ comp.D[:, m:]
    Bu = comp.B[:, :m]
    return comp.A + Bu @ Cu, comp.B[:, m:] + Bu @ Dwu, Cu, Dwu


def from_statespace(
    ss: control.StateSpace,
    *,
    x0: Sequence[float] | None = None,
    u0: Sequence[float] | None = None,
    system: str = "",
) -> LinearModel:
    """A :class:`LinearModel` from a ``control.StateSpace``.

    Parameters
    ----------
    ss:
        A python-control state-space system; its signal labels become the
        names. ``dt = 0`` is continuous; ``dt = True`` (discrete with an
        unspecified period) is refused.
    x0, u0:
        The operating point the model is a linearization about (default zero).
    system:
        The system key to record.
    """
    import control

    if not isinstance(ss, control.StateSpace):
        raise DesignError(f"from_statespace needs a control.StateSpace, got {type(ss).__name__}")
    dt = ss.dt
    if dt is True:
        raise DesignError(
            "the StateSpace is discrete with an unspecified period (dt=True): give dt"
        )
    A = np.asarray(ss.A, dtype=float)
    n, m = A.shape[0], np.asarray(ss.B).shape[1]
    return LinearModel(
        A=A,
        B=np.asarray(ss.B, dtype=float),
        C=np.asarray(ss.C, dtype=float),
        D=np.asarray(ss.D, dtype=float),
        state_names=tuple(ss.state_labels),
        input_names=tuple(ss.input_labels),
        output_names=tuple(ss.output_labels),
        x0=np.zeros(n) if x0 is None else checks.matrix([x0], "x0", (1, n))[0],
        u0=np.zeros(m) if u0 is None else checks.matrix([u0], "u0", (1, m))[0],
        system=system,
        dt=None if not dt else float(dt),
    )


def loop_at_input(design: Design, *, controller: str = "lqg") -> control.StateSpace:
    """The loop as implemented, broken at the plant input, as a python-control system.

    The open loop ``L = C(s) P(s)`` from a signal injected at the plant's
    input to the signal returned there, in **negative feedback**: the loop
    closes as ``u = -L u`` (characteristic equation ``1 + L = 0``), so
    ``control.stability_margins(loop_at_input(d))`` gives the margins
    ``d.margins`` reports (python-control's gain margin is the one of
    ``gain_lower``, ``gain_upper`` nearer to 1). Its input is the plant's
    input (``"F"``), its output that input's return (``"F_return"``): minus
    the command the controller computes from the plant's response. It is
    in the design's timebase: continuous for a continuous design, discrete
    with ``dt = 1 / rate`` for a sampled one (the discrete plant
    ``d.discrete`` and the compensator's discrete form, the matrices the
    simulator and the C export run).

    Parameters
    ----------
    design:
        A :class:`~equilibrist.control.design.Design`.
    controller:
        ``"lqg"`` (default): the compensator ``d.compensator`` (the Kalman
        filter on the measured outputs, fed its own command, and ``u = -K
        xhat``; references held at zero) in series with the plant, states
        ``plant states + xhat_<state>``. LQG has no guaranteed margins:
        these are usually well below the state feedback's. ``"lqr"``: the
        state feedback on the measured full state, ``L = K (sI - A)^-1 B``
        (``d.lqr_margins``).

        A design for a delayed loop (``d.delay = N``) gives the loop as it runs: the
        plant with its line of ``N`` commands in flight (``d.discrete``, fed the injected
        signal) in series with the controller that holds its own record of the commands it
        sent, fed its own command (``"lqr"``: ``u = -Kx x - Ku b``, states ``plant states,
        F_sent<k>, record_F_sent<k>``; ``"lqg"``: the Kalman filter of the extended model,
        ``d.compensator``), the controller
        :meth:`~equilibrist.control.linear.LinearController.from_design` makes. Not
        ``K (zI - A)^-1 B`` of the extended model, which would count the controller's record
        as part of the plant.

    Notes
    -----
    Continuous loops: ``control.stability_margins(loop_at_input(d))``
    agrees with ``d.margins`` to rounding. Sampled loops: python-control's
    polynomial method finds spurious crossovers when the plant has poles
    at ``z = 1`` (the cart-pole's position), and its default falls back to
    an interpolated frequency response on a coarse grid (gain and phase
    margins good to about 1e-4, its ``|1 + L|`` minimum unreliable). On a
    dense grid up to the Nyquist frequency it agrees to rounding::

        L = loop_at_input(d)
        w = numpy.logspace(-2, numpy.log10(numpy.pi / L.dt), 200_000)[:-1]
        control.stability_margins(control.frd(L, w))

    (see :func:`~equilibrist.control.analysis.loop_margins`).
    """
    return to_statespace(_loop_model(design, controller=controller), name="loop")


def _loop_model(design: Design, *, controller: str = "lqg") -> LinearModel:
    """:func:`loop_at_input`'s system as a :class:`LinearModel` (numpy only, no python-control).

    With the plant ``x+ = A x + B v``, ``y = C x + Dp v`` and the
    compensator ``xc+ = Ac xc + Bu u + By y``, ``u = Cc xc + Du u + Dy y``
    (references zero) whose ``u`` input is its own command ``u``: the loop
    has the states ``[x; xc]`` and returns ``-u``.
    """
    if controller not in LOOP_CONTROLLERS:
        raise DesignError(
            f"the loop of controller {controller!r} is not a design's: expected "
            f"{' or '.join(LOOP_CONTROLLERS)}"
        )
    plant = design.model
    m = plant.n_inputs
    inputs = plant.input_names
    outputs = tuple(f"{name}_return" for name in inputs)
    if controller == "lqr" and design.delay:
        return _delayed_lqr_loop(design)
    if controller == "lqr":
        A, B = plant.A, plant.B
        C, D = np.asarray(design.K, dtype=float), np.zeros((m, m))
        states = plant.state_names
    else:
        comp = design.compensator
        p = plant.n_outputs
        Bu, By = comp.B[:, :m], comp.B[:, m : m + p]
        Du, Dy = comp.D[:, :m], comp.D[:, m : m + p]
        # The command u = Cc xc + Du u + Dy y, solved for u (Du is zero in every form).
        close = np.linalg.inv(np.eye(m) - Du)
        Cu, Dyu = close @ comp.C, close @ Dy
        Ac = comp.A + Bu @ Cu
        Bc = By + Bu @ Dyu
        n, nc = plant.n_states, comp.n_states
        A = np.block([[plant.A, np.zeros((n, nc))], [Bc @ plant.C, Ac]])
        B = np.vstack([plant.B, Bc @ plant.D])
        C = -np.hstack([Dyu @ plant.C, Cu])
        D = -Dyu @ plant.D
        states = plant.state_names + comp.state_names
    return LinearModel(
        A=np.asarray(A, dtype=float),
        B=np.asarray(B, dtype=float),
        C=np.asarray(C, dtype=float).reshape(m, -1),
        D=np.asarray(D, dtype=float).reshape(m, m),
        state_names=tuple(states),
        input_names=inputs,
        output_names=outputs,
        x0=np.zeros(len(states)),
        u0=np.zeros(m),
        system=design.system_key,
        dt=plant.dt,
    )


def _delayed_lqr_loop(design: Design) -> LinearModel:
    """The loop of a delayed design's LQR as it runs, broken at the plant's input: the plant
    with its delay line (the extended model, fed the signal injected there) in series with
    the controller, whose own record of the commands in flight is fed its own command
    (``u = -Kx x - Ku b``, ``b`` shifted and given ``u``); it returns ``-u``. The state
    feedback on the extended model, ``K (zI - A)^-1 B``, would count the controller's record
    as part of the plant: an error in the actuator's gain would then reach the record too,
    and the margins would be those of a loop that does not run."""
    model = design.model
    n, size, m = design.plant.n_states, model.n_states, model.n_inputs
    nb = size - n
    K = np.asarray(design.K, dtype=float)
    Kx, Ku = K[:, :n], K[:, n:]
    shift, enter = model.A[n:, n:], model.B[n:, :]
    A = np.zeros((size + nb, size + nb))
    A[:size, :size] = model.A
    A[size:, :n] = -enter @ Kx
    A[size:, size:] = shift - enter @ Ku
    B = np.vstack([model.B, np.zeros((nb, m))])
    C = np.hstack([Kx, np.zeros((m, nb)), Ku])
    states = model.state_names + tuple(f"record_{s}" for s in model.state_names[n:])
    return LinearModel(
        A=A, B=B, C=C, D=np.zeros((m, m)), state_names=states, input_names=model.input_names,
        output_names=tuple(f"{name}_return" for name in model.input_names),
        x0=np.zeros(size + nb), u0=np.zeros(m), system=design.system_key, dt=model.dt)

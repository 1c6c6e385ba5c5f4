"""LQR + Kalman (LQG) design for a system of the catalogue at its canonical point.

:func:`design` linearizes the system at its canonical operating point,
chooses the weights, and returns a frozen :class:`Design` holding every
gain and covariance that the simulation and the C export use.

Default weights (SYSTEMS.md, "Control and estimation"; each system's spec):

* ``Q = diag(1 / scale_i^2)`` over the states and ``R = diag(1 / scale_j^2)``
  over the inputs from ``spec.design_scales`` (Bryson's rule: the largest
  acceptable deviation of each state and input on the real rig).
* ``RN = diag(sensor_noise_i^2) * T`` over the measured outputs: the spec
  gives the sensors' per-sample standard deviations, and ``Rd = RN / T``
  then equals their variance. ``T`` is the design's sample period, or the
  rig's ``control_rate`` for a continuous design.
* ``QN = diag(process_noise_i^2)`` with ``G = I``: noise on the states that
  ``spec.process_noise`` names (the rates), zero on the others. When that
  leaves a mode on the stability boundary unexcited (the servo ball and
  beam's beam angle, an integrator of the input only), the Kalman Riccati
  equation has no stabilizing solution; then, and only then, the states of
  those modes that have no process noise get a floor of ``(1e-3 * design_scale_i)^2`` --
  small against the real noise, in the state's own units -- and the design
  records it in :attr:`Design.notes`. The floor makes the problem well posed,
  not the filter fast: the estimate of such a state converges with a time
  constant of about ``sensor_noise / (1e-3 * design_scale)`` (some 20 s for
  the servo ball and beam's beam angle); a spec that knows its real process
  noise there should say so.

A scale or noise level that the spec does not give is never invented: the
error names it and asks for the weight explicitly.

Discrete designs (``rate`` in Hz) sample the plant (``"zoh"`` or ``"euler"``,
see :mod:`~equilibrist.control.discretize`), use the same ``Q`` and ``R`` as
per-sample weights (``sum_k x_k'Q x_k + u_k'R u_k``; the ratio of the weights
is what shapes the gain, so the gain tends to the continuous one as the rate
grows), and the per-sample noise covariances ``Qd`` (Van Loan) and
``Rd = RN / dt``.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, cast

import numpy as np

from equilibrist.control import checks
from equilibrist.control.design_cache import (
    _kept_on_disk,
)
from equilibrist.control.design_extended import delay_periods, delayed, velocity_filtered
from equilibrist.control.design_record import Design, _sorted
from equilibrist.control.discretize import (
    METHODS,
    discrete_noise,
    discretize,
)
from equilibrist.control.kalman import FORMS
from equilibrist.control.reference import discrete_reference_gain, reference_gain
from equilibrist.control.riccati import (
    current_gain,
    dlqe,
    dlqr,
    lqe,
    lqr,
)
from equilibrist.control.weights import (
    MAX_RATE,
    _bryson,
    _default_process_noise,
    _weight,
)
from equilibrist.errors import DesignError

if TYPE_CHECKING:
    from equilibrist.numeric.linear import LinearModel
    from equilibrist.numeric.system import System


@_kept_on_disk
def design(
    system: System,
    *,
    q: object | None = None,
    r: object | None = None,
    qn: object | None = None,
    rn: object | None = None,
    outputs: Sequence[str] | None = None,
    rate: float | None = None,
    discretization: str = "zoh",
    kalman_form: str = "current",
    G: object | None = None,
    at: Mapping[str, float] | None = None,
    delay: int = 0,
    velocity_filter: float = 0.0,
) -> Design:
    """Design LQR, Kalman filter and reference gain for *system* at its canonical point.

    With *at*, the design is made at another operating point: the
    equilibrium with the given states (``{"theta": math.pi}``), its other
    components solved as for the canonical one. With *delay*, the design compensates
    a loop that many control periods late (:func:`~equilibrist.control.design_extended.delayed`).

    Parameters
    ----------
    system:
        A bound :class:`~equilibrist.numeric.system.System` with at least one input.
    q, r:
        LQR weights: a vector (the diagonal; one value per state / input) or
        a square matrix. Default: Bryson's rule from the spec's design scales.
    qn:
        Process noise intensity: one value per noise input (the diagonal) or
        a square matrix. Default: the spec's process noise (see the module
        docstring for the floor).
    rn:
        Measurement noise intensity: one value per output, or a matrix.
        Default: the spec's sensor noise squared.
    outputs:
        Measured outputs (state names); default the spec's. The first ``m``
        are tracked by the reference gain.
    rate:
        Sample rate [Hz] for a discrete design; None for continuous.
    discretization:
        ``"zoh"`` or ``"euler"``.
    kalman_form:
        ``"current"`` or ``"predictor"`` (which discrete gain is ``Kf``).
    G:
        Noise input matrix (``n x k``); default the identity (``k = n``).
    at:
        States of the operating point to design at (the others solved);
        None: the canonical operating point.
    delay:
        The loop's delay in whole control periods that the design compensates (a command
        acting that many periods after it is sent, or a measurement that many periods
        late): the gains are designed on the sampled plant extended by the commands in
        flight (:func:`~equilibrist.control.design_extended.delayed`). Needs a *rate*. Default 0: the design of the plant as
        it is.
    velocity_filter:
        The cutoff [Hz] of the rig's low-pass of the measured joint rates
        (:class:`~equilibrist.sim.rig.Rig`'s ``velocity_filter``) the Kalman filter's model
        includes, so that it estimates the plant's state from the filtered rates without
        their lag (:func:`~equilibrist.control.design_extended.velocity_filtered`); the measured outputs that are joints' rates
        are the filtered ones, as the rig filters them. Needs a *rate* and a measured rate;
        not with a *delay* (yet). Default 0: the rates as measured.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        A system without input; weights that are not (semi)definite; a
        missing design scale or noise level; an uncontrollable or
        unobservable pair; a rate that is not positive; an unknown option.
    DimensionError
        Weights of the wrong size.
    UnknownNameError
        An output that is not a state.
    """
    from equilibrist.numeric.system import System as _System

    if not isinstance(system, _System):
        raise DesignError(f"system = {system!r}: expected a System (equilibrist.get_system(name)), "
                          f"not {type(system).__name__}")
    discretization, kalman_form, rate_hz = _checked_options(
        system, outputs=outputs, at=at, discretization=discretization, kalman_form=kalman_form,
        rate=rate, delay=delay, velocity_filter=velocity_filter,
    )
    if system.n_inputs == 0:
        raise DesignError(f"{system.key} has no input: there is no controller to design")
    names = tuple(system.output_names if outputs is None else outputs)
    plant = _operating_plant(system, names, at=at, rate_hz=rate_hz)
    weights = _design_weights(system, plant, names, q=q, r=r, qn=qn, rn=rn, G=G, rate_hz=rate_hz)
    made = _solved(system, plant, names, weights, rate_hz=rate_hz,
                   discretization=discretization, kalman_form=kalman_form)
    if velocity_filter:
        return velocity_filtered(made, float(velocity_filter), rate_outputs(system, names))
    return delayed(made, int(delay)) if delay else made


def rate_outputs(system: System, outputs: Sequence[str]) -> tuple[str, ...]:
    """The *outputs* the rig's velocity filter acts on: those that are a joint's rate (a
    state ``q_dot`` of a state ``[q, q_dot]``), as :mod:`equilibrist.sim.rig` picks them."""
    nq = int(system.functions.N_Q)
    if nq == 0 or system.n_states != 2 * nq:
        return ()
    rates = system.state_names[nq:]
    return tuple(o for o in outputs if o in rates)


def _checked_options(
    system: System,
    *,
    outputs: Sequence[str] | None,
    at: Mapping[str, float] | None,
    discretization: str,
    kalman_form: str,
    rate: float | None,
    delay: object = 0,
    velocity_filter: object = 0.0,
) -> tuple[str, str, float | None]:
    """The options of :func:`design` checked, every problem at once: the discretization and
    Kalman form (the defaults in place of one that is not a string) and the rate in Hz.

    Raises :class:`DesignError` naming every problem."""
    problems: list[str] = []
    if outputs is not None and (isinstance(outputs, str | bytes) or not isinstance(outputs, Sequence)
                                or not all(isinstance(o, str) for o in outputs)):
        problems.append(f"outputs = {outputs!r}: expected a list of state names")
    if at is not None and not isinstance(at, Mapping):
        problems.append(f"at = {at!r}: expected a mapping {{state: value}}")
    elif at:
        for key, value in at.items():
            if not isinstance(key, str):
                problems.append(f"at: {key!r} is not a state name of {system.key} "
                                f"({', '.join(system.state_names)})")
            elif isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) \
                    or not math.isfinite(float(value)):
                problems.append(f"at: {key} = {value!r} is not a finite number")
    if not isinstance(discretization, str):
        problems.append(f"discretization = {discretization!r}: expected one of {', '.join(METHODS)}")
        discretization = "zoh"
    if not isinstance(kalman_form, str):
        problems.append(f"kalman_form = {kalman_form!r}: expected one of {', '.join(FORMS)}")
        kalman_form = "current"
    if discretization not in METHODS:
        problems.append(
            f"discretization {discretization!r} is unknown: expected one of {', '.join(METHODS)}"
        )
    if kalman_form not in FORMS:
        problems.append(
            f"kalman form {kalman_form!r} is unknown: expected one of {', '.join(FORMS)}"
        )
    rate_hz: float | None = None
    if rate is not None:
        try:
            rate_hz = float(rate)
        except (TypeError, ValueError):
            problems.append(
                f"rate must be a positive number of samples per second (Hz), got {rate!r}"
            )
        else:
            if not math.isfinite(rate_hz) or rate_hz <= 0:
                problems.append(
                    f"rate must be a positive number of samples per second (Hz), got {rate_hz:g}"
                )
    if isinstance(delay, bool) or not isinstance(delay, int | np.integer) or delay < 0:
        problems.append(f"delay = {delay!r}: expected a whole number of control periods >= 0")
    elif delay and rate is None:
        problems.append(f"delay = {delay}: a delay in control periods needs a discrete design "
                        "(give a rate)")
    if isinstance(velocity_filter, bool) or not isinstance(
            velocity_filter, int | float | np.integer | np.floating) \
            or not math.isfinite(float(velocity_filter)) or velocity_filter < 0:
        problems.append(f"velocity_filter = {velocity_filter!r}: expected a cutoff in Hz > 0 "
                        "(0: none)")
    elif velocity_filter:
        if rate is None:
            problems.append(f"velocity_filter = {velocity_filter:g} Hz: the rig's filter of "
                            "samples needs a discrete design (give a rate)")
        if delay:
            problems.append("velocity_filter and delay together are not designed yet: give one")
        if outputs is not None and isinstance(outputs, Sequence) and not rate_outputs(
                system, [o for o in outputs if isinstance(o, str)]):
            problems.append(f"velocity_filter = {velocity_filter:g} Hz: no measured output is a "
                            "joint's rate (the rig filters measured rates): measure them "
                            "(outputs=...)")
        elif outputs is None and not rate_outputs(system, system.output_names):
            problems.append(f"velocity_filter = {velocity_filter:g} Hz: no measured output of "
                            f"{system.key} ({', '.join(system.output_names)}) is a joint's "
                            "rate (the rig filters measured rates): measure them (outputs=...)")
    checks.raise_if(problems)
    return discretization, kalman_form, rate_hz


def _operating_plant(
    system: System, names: tuple[str, ...], *, at: Mapping[str, float] | None,
    rate_hz: float | None,
) -> LinearModel:
    """*system* linearized with the outputs *names*, at its canonical operating point or at
    the equilibrium with the states *at*; a rate too fast or too slow for it is refused.

    Raises :class:`DesignError` for no output or a repeated one, no equilibrium at *at*, or
    the rate."""
    if not names:
        raise DesignError("no measured outputs: the estimator needs at least one")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DesignError(f"outputs lists {', '.join(repeated)} more than once")
    # A smooth Coulomb law's slope at rest (100 cf) is no damping a controller can count on:
    # the plant is linearized with it at zero, at the same operating point (it acts at rest).
    coulomb = {p.name: 0.0 for p in system.spec.all_parameters if p.coulomb}
    given = system
    system = system.with_params(**coulomb) if coulomb else system
    if at:
        eq = system.equilibrium(state={k: float(v) for k, v in at.items()})
        if eq.residual > 1e-6 * (1.0 + float(np.max(np.abs(eq.x)))):
            raise DesignError(
                f"{system.key} has no equilibrium with "
                + ", ".join(f"{k} = {v:g}" for k, v in at.items())
                + f" (the closest point leaves |f| = {eq.residual:.3g})"
            )
        plant = system.linearize(eq.x, eq.u, outputs=names)
    else:
        plant = system.linearize(outputs=names)
    if coulomb:
        plant = replace(plant, params=given.params)
    n = plant.n_states
    if rate_hz is not None and rate_hz > MAX_RATE:
        # Past this the sampled plant is the identity to double precision (an
        # input moves the state by ~dt^2 per sample) and every mode looks
        # uncontrollable: the rate is the problem, not the plant.
        raise DesignError(
            f"a rate of {rate_hz:g} Hz is too fast to design for: at dt = {1 / rate_hz:.3g} s the "
            f"sampled plant is the identity to within double precision; design at "
            f"{MAX_RATE:g} Hz or less (real rigs sample at 10 Hz to 100 kHz)"
        )
    if rate_hz is not None:
        # A mode that grows by e^10 within one sample cannot be held by a
        # sampled controller (and e^400 overflows the discretization).
        fastest = float(np.max(np.abs(np.linalg.eigvals(plant.A)))) if n else 0.0
        if fastest / rate_hz > 10.0:
            raise DesignError(
                f"a rate of {rate_hz:g} Hz is too slow for {system.key}: its fastest mode, "
                f"{fastest:.4g} rad/s, changes by e^{fastest / rate_hz:.3g} within one sample; "
                f"sample at {10 * fastest / (2 * math.pi):.3g} Hz or more"
            )
    return plant


@dataclass(frozen=True)
class _Weights:
    """The weights of a design: LQR's ``Q``, ``R``; the noise intensities ``QN`` (on the
    noise inputs ``G``) and ``RN``; and the notes on a process-noise floor."""

    Q: np.ndarray
    R: np.ndarray
    QN: np.ndarray
    RN: np.ndarray
    G: np.ndarray
    notes: tuple[str, ...]


def _design_weights(
    system: System, plant: LinearModel, names: tuple[str, ...], *, q: object | None,
    r: object | None, qn: object | None, rn: object | None, G: object | None,
    rate_hz: float | None,
) -> _Weights:
    """The weights: the user's, or the defaults from the spec (see the module docstring).

    Raises :class:`DesignError` naming every problem at once (a missing design scale or
    noise level, a weight that is not (semi)definite)."""
    states, inputs = plant.state_names, plant.input_names
    n = plant.n_states
    problems: list[str] = []
    missing: list[str] = []
    Q = (
        _bryson(system, states, missing)
        if q is None
        else _weight(q, "q", states, definite=False, problems=problems)
    )
    R = (
        _bryson(system, inputs, missing)
        if r is None
        else _weight(r, "r", inputs, definite=True, problems=problems)
    )
    if missing:
        need = " and ".join(
            w
            for w, present in (
                ("q", any(s in missing for s in states)),
                ("r", any(i in missing for i in inputs)),
            )
            if present
        )
        problems.append(
            f"{system.key} has no design scale for {', '.join(missing)} in its spec "
            f"(Bryson's rule needs the largest acceptable deviation of each): give {need}"
        )
    if rn is None:
        noise = system.spec.sensor_noise
        absent = [o for o in names if not noise.get(o, 0) > 0]
        if absent:
            problems.append(
                f"{system.key} gives no sensor noise for output(s) {', '.join(absent)} in its "
                f"spec: give rn (one value per output: {', '.join(names)})"
            )
            RN = np.eye(len(names))
        else:
            # The spec's sensor noise is a per-sample standard deviation;
            # RN is a spectral density with Rd = RN / T, so RN = sigma^2 T
            # makes the sampled sensor noise the stated one.
            t_sample = 1.0 / (rate_hz if rate_hz is not None else system.spec.control_rate)
            RN = np.diag([float(noise[o]) ** 2 * t_sample for o in names])
    else:
        RN = _weight(rn, "rn", names, definite=True, problems=problems)
    notes: tuple[str, ...] = ()
    if G is None:
        Gm = np.eye(n)
        noise_labels: tuple[str, ...] = states
    else:
        Gm = checks.with_rows(G, "G", n, "one per state")
        noise_labels = tuple(f"noise input {j}" for j in range(Gm.shape[1]))
    if qn is None:
        if G is not None and Gm.shape[1] != n:
            raise DesignError(
                f"G has {Gm.shape[1]} noise inputs: give qn with one value per noise input"
            )
        if not problems:
            QN, notes = _default_process_noise(system, plant)
        else:
            QN = np.eye(n)
    else:
        QN = _weight(qn, "qn", noise_labels, definite=False, problems=problems)
    checks.raise_if(problems)
    return _Weights(Q=Q, R=R, QN=QN, RN=RN, G=Gm, notes=notes)


def _solved(
    system: System, plant: LinearModel, names: tuple[str, ...], weights: _Weights, *,
    rate_hz: float | None, discretization: str, kalman_form: str,
) -> Design:
    """The gains for *weights*, continuous or (with a rate) sampled: LQR, the Kalman filter,
    the reference gain of the first ``m`` outputs (or why there is none), as a
    :class:`Design`."""
    states, inputs = plant.state_names, plant.input_names
    n, m = plant.n_states, plant.n_inputs
    Q, R, QN, RN, Gm = weights.Q, weights.R, weights.QN, weights.RN, weights.G
    tracked = names[:m] if len(names) >= m else ()
    Cr = plant.C[:m] if tracked else None
    Kc: np.ndarray | None = None
    kc_note = ""
    gain_rule: Callable[..., np.ndarray]  # the continuous or the sampled reference gain
    if rate_hz is None:
        K, S, E = lqr(plant.A, plant.B, Q, R, state_names=states)
        Kf, P, Ef = lqe(plant.A, Gm, plant.C, QN, RN, state_names=states, output_names=names)
        disc, Qd, Rd = None, None, None
        Ar, Br, gain_rule = plant.A, plant.B, reference_gain
    else:
        dt = 1.0 / rate_hz
        disc = discretize(plant, dt, method=discretization)
        Qd, Rd = discrete_noise(plant.A, Gm, QN, RN, dt, method=discretization)
        K, S, E = dlqr(disc.A, disc.B, Q, R, state_names=states)
        L, P, Ef = dlqe(disc.A, np.eye(n), disc.C, Qd, Rd, state_names=states, output_names=names)
        Kf = current_gain(P, disc.C, Rd) if kalman_form == "current" else L
        Ar, Br, gain_rule = disc.A, disc.B, discrete_reference_gain
    if Cr is not None:
        try:
            Kc = gain_rule(Ar, Br, Cr, K, tracked_names=tracked, input_names=inputs)
        except DesignError as exc:
            kc_note = str(exc)
    else:
        kc_note = (
            f"{len(names)} measured output(s) for {m} inputs: the reference gain tracks the "
            f"first {m} outputs"
        )
    discrete = rate_hz is not None
    return Design(
        system_key=system.key,
        params=types.MappingProxyType(dict(system.params)),
        plant=plant,
        Q=Q,
        R=R,
        QN=QN,
        RN=RN,
        G=Gm,
        rate=rate_hz,
        discretization=discretization,
        kalman_form=kalman_form,
        discrete=disc,
        K=K,
        S=S,
        poles=_sorted(E, discrete),
        Kf=Kf,
        P=P,
        Kc=Kc,
        kc_note=kc_note,
        Qd=Qd,
        Rd=Rd,
        tracked=tracked,
        estimator_poles=_sorted(Ef, discrete),
        notes=weights.notes,
    )


def kind_design(made: Design, system: System, options: Mapping[str, object]) -> Design:
    """The design the ``lqr`` and ``lqg`` kinds' options ask for, from *made* (the request's
    design of *system*): ``design_delay`` (``--design-delay N|Ts``, :func:`~equilibrist.control.design_extended.delayed`) and
    ``design_velocity_filter`` (``--design-velocity-filter HZ``, :func:`~equilibrist.control.design_extended.velocity_filtered` of
    the measured outputs that are joints' rates). Neither given: *made* itself.

    Raises
    ------
    DesignError
        A continuous design, both options at once, a filter with no measured rate, a value
        :func:`~equilibrist.control.design_extended.delay_periods` or :func:`~equilibrist.control.design_extended.velocity_filtered` refuses.
    """
    delay, cutoff = options.get("design_delay"), options.get("design_velocity_filter")
    if (delay is not None or cutoff is not None) and made.rate is None:
        raise DesignError("--design-delay and --design-velocity-filter need a rate: they "
                          "design a sampled loop")
    periods = 0 if delay is None or made.rate is None else delay_periods(delay, made.rate)
    if cutoff is None:
        return delayed(made, periods)
    if periods:
        raise DesignError("--design-velocity-filter and --design-delay together are not "
                          "designed yet: give one")
    rates = rate_outputs(system, made.output_names)
    if not rates:
        raise DesignError(f"--design-velocity-filter: no measured output of {system.key} "
                          f"({', '.join(made.output_names)}) is a joint's rate (the rig "
                          "filters measured rates): measure them (--outputs)")
    return velocity_filtered(made, cast(float, cutoff), rates)


__all__ = [
    "design",
    "kind_design",
    "rate_outputs",
]

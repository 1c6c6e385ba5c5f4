"""Designs on an extended model: a discrete design made again for a loop that is late by
whole control periods (:func:`delayed`, the commands in flight as states), or for measured
rates read through the rig's velocity filter (:func:`velocity_filtered`, the filter's
outputs as states), and the loop delay of the command line in periods
(:func:`delay_periods`). Each takes the design :func:`~equilibrist.control.design.design`
made and returns its record on the extended model (docs/controllers.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.design_record import Design, _sorted
from equilibrist.control.discretize import (
    velocity_filter_gain,
    with_input_delay,
    with_velocity_filter,
)
from equilibrist.control.reference import discrete_reference_gain
from equilibrist.control.riccati import current_gain, dlqe, dlqr
from equilibrist.errors import DesignError

if TYPE_CHECKING:
    from equilibrist.numeric.linear import LinearModel


def delayed(made: Design, periods: int) -> Design:
    """*made*, a discrete design, designed again for a loop *periods* control periods late.

    The model is the sampled plant extended by the commands sent but not yet acted
    (:func:`~equilibrist.control.discretize.with_input_delay`:
    ``x_{k+1} = Ad x_k + Bd u_{k-N}``, the state ``[x; u_{k-N}; ...; u_{k-1}]``), and every
    gain is that model's:

    * the LQR minimizes the same ``sum x'Q x + u'R u`` on it (the commands in flight
      weighed by zero), so ``K = [Kx, K_{N}, ..., K_{1}]`` acts on the plant's state and
      on each command in flight (the undelayed gain on the state predicted over the
      delay);
    * the Kalman filter is the stationary filter of that model with the process noise on
      the plant's states only: the commands in flight are known exactly, so its a-priori
      covariance is the undelayed one's ``P`` beside zeros, the stabilizing solution of
      the extended model's Riccati equation, and its gain is the undelayed gain beside
      zeros. It estimates the plant's state the measurements describe and predicts with
      the command sent ``N`` periods before;
    * the reference gain is the extended loop's (the same steady state);
    * the closed-loop poles are the undelayed design's and ``N m`` at ``z = 0``: with the
      prediction the loop is the undelayed one, ``N`` periods later.

    The weights ``Q, R, QN, RN, G`` stay the plant's (what was asked); ``discrete``,
    ``K, S, poles, Kf, P, Qd, Kc, estimator_poles`` are the extended model's, and
    :attr:`Design.delay` is *periods*. ``periods = 0`` returns *made*.

    Raises
    ------
    DesignError
        A continuous design, a design already delayed, or *periods* not a whole number >= 0.
    """
    if isinstance(periods, bool) or not isinstance(periods, int | np.integer) or periods < 0:
        raise DesignError(f"delay = {periods!r}: expected a whole number of control periods >= 0")
    if periods == 0:
        return made
    if made.discrete is None or made.rate is None or made.Qd is None or made.Rd is None:
        raise DesignError("a delay in control periods needs a discrete design (give a rate)")
    if made.delay:
        raise DesignError(f"the design already compensates a delay of {made.delay} period(s): "
                          "delay the design made without one")
    if made.velocity_filter:
        raise DesignError("velocity_filter and delay together are not designed yet: give one")
    N = int(periods)
    model = with_input_delay(made.discrete, N)
    n, size = made.discrete.n_states, model.n_states
    Q = np.zeros((size, size))
    Q[:n, :n] = made.Q
    K, S, _E = dlqr(model.A, model.B, Q, made.R, state_names=model.state_names)
    # The loop with the predictor is the undelayed loop N periods later: its poles are the
    # undelayed design's and N m at z = 0 (a nilpotent block, whose computed eigenvalues
    # scatter about 0 by ~1e-8 and would read as poles of 1700 rad/s).
    E = np.concatenate([made.poles, np.zeros(size - n, dtype=complex)])
    P = np.zeros((size, size))
    P[:n, :n] = made.P
    Qd = np.zeros((size, size))
    Qd[:n, :n] = made.Qd
    M = current_gain(P, model.C, made.Rd)
    L = fixed.matmul(model.A, M)
    Kf = M if made.kalman_form == "current" else L
    Kc, kc_note = _extended_reference_gain(made, model, K)
    return replace(
        made, discrete=model, K=K, S=S, poles=_sorted(E, True), Kf=Kf, P=P, Qd=Qd, Kc=Kc,
        kc_note=kc_note, estimator_poles=_sorted(np.linalg.eigvals(model.A - L @ model.C), True),
        delay=N,
    )


def _extended_reference_gain(made: Design, model: LinearModel, K: np.ndarray
                             ) -> tuple[np.ndarray | None, str]:
    """The reference gain of *made*'s loop on its extended *model* with gain *K* (and the
    note of why there is none), or *made*'s own when it tracks nothing."""
    if not made.tracked:
        return made.Kc, made.kc_note
    try:
        return discrete_reference_gain(model.A, model.B, model.C[:model.n_inputs], K,
                                       tracked_names=made.tracked,
                                       input_names=model.input_names), ""
    except DesignError as exc:
        return None, str(exc)


def velocity_filtered(made: Design, cutoff: float, outputs: Sequence[str]) -> Design:
    """*made*, a discrete design, with its Kalman filter designed again for measured *outputs*
    read through the rig's velocity filter of cutoff *cutoff* [Hz]
    (:class:`~equilibrist.sim.rig.Rig`'s ``velocity_filter``: ``v_f += a (v - v_f)``,
    ``a = 1 - exp(-2 pi f_c T)``, per measured rate).

    The model is the sampled plant extended by the filter's last outputs
    (:func:`~equilibrist.control.discretize.with_velocity_filter`), and

    * the Kalman filter is the stationary filter of that model with the process noise on the
      plant's states and the design's measurement noise on the filtered outputs: it
      estimates the plant's state (and the filter's) from the filtered rates, their lag
      accounted for;
    * the LQR is the plant's, beside zeros: the filter's states change nothing the plant
      does (``K = [K, 0]``, ``S = [[S, 0], [0, 0]]``), so the closed-loop poles are the
      plant's and the filter's own, ``1 - a``, once per filtered output;
    * the reference gain is the extended loop's (the same steady state).

    ``discrete``, ``K, S, poles, Kf, P, Qd, Kc, estimator_poles`` are the extended model's;
    :attr:`Design.velocity_filter` is *cutoff* and :attr:`Design.filtered` the *outputs*.
    Only the LQG runs on such a design (the LQR reads the state as it is measured).

    Raises
    ------
    DesignError
        A continuous or delayed design, one already filtered, a cutoff that is not a
        positive number, *outputs* the design does not measure.
    """
    if isinstance(cutoff, bool) or not isinstance(cutoff, int | float | np.integer | np.floating) \
            or not math.isfinite(float(cutoff)) or cutoff <= 0:
        raise DesignError(f"velocity_filter = {cutoff!r}: expected a cutoff in Hz > 0")
    if made.discrete is None or made.rate is None or made.Qd is None or made.Rd is None:
        raise DesignError("a velocity filter of samples needs a discrete design (give a rate)")
    if made.extended:
        raise DesignError("the design's model is already extended (a delay or a filter): "
                          "filter the design made without one")
    names = tuple(outputs)
    gain = velocity_filter_gain(cutoff, made.rate)
    model = with_velocity_filter(made.discrete, names, gain)
    n, size = made.discrete.n_states, model.n_states
    K = np.hstack([made.K, np.zeros((made.K.shape[0], size - n))])
    S = np.zeros((size, size))
    S[:n, :n] = made.S
    Qd = np.zeros((size, size))
    Qd[:n, :n] = made.Qd
    L, P, Ef = dlqe(model.A, np.eye(size), model.C, Qd, made.Rd,
                    state_names=model.state_names, output_names=model.output_names)
    Kf = current_gain(P, model.C, made.Rd) if made.kalman_form == "current" else L
    E = np.concatenate([made.poles, np.full(size - n, 1.0 - gain, dtype=complex)])
    Kc, kc_note = _extended_reference_gain(made, model, K)
    return replace(
        made, discrete=model, K=K, S=S, poles=_sorted(E, True), Kf=Kf, P=P, Qd=Qd, Kc=Kc,
        kc_note=kc_note, estimator_poles=_sorted(Ef, True), velocity_filter=float(cutoff),
        filtered=names,
    )


def delay_periods(value: object, rate: float) -> int:
    """A loop delay as whole control periods at *rate* [Hz]: *value* is a whole number of
    periods (``2``, ``"2"``) or seconds as text (``"4ms"``, ``"0.004s"``), which must be a
    whole number of periods at *rate* (``0.004s`` at 500 Hz is 2; at 200 Hz, 0.8 periods,
    it is refused). The command line's ``--design-delay``.

    Raises
    ------
    DesignError
        A value of neither form, a negative one, or seconds that are no whole number of
        periods (naming how many periods they are).
    """
    expected = "a whole number of control periods >= 0, or seconds (4ms, 0.004s)"
    if isinstance(value, bool):
        raise DesignError(f"design delay {value!r}: expected {expected}")
    if isinstance(value, int | np.integer):
        if value < 0:
            raise DesignError(f"design delay {value}: expected {expected}")
        return int(value)
    word = str(value).strip()
    scale = 1e-3 if word.endswith("ms") else 1.0 if word.endswith("s") else None
    try:
        if scale is None:
            periods = int(word)
            if periods < 0:
                raise ValueError(word)
            return periods
        seconds = float(word[: -2 if scale == 1e-3 else -1]) * scale
    except ValueError:
        raise DesignError(f"design delay {word!r}: expected {expected}") from None
    exact = seconds * float(rate)
    if not (math.isfinite(exact) and exact >= 0):
        raise DesignError(f"design delay {word!r}: expected {expected}")
    whole = round(exact)
    if abs(exact - whole) > 1e-9 * max(1.0, exact):
        raise DesignError(f"design delay {word} is {exact:g} control periods at {rate:g} Hz: "
                          "expected a whole number of periods")
    return int(whole)

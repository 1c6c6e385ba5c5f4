"""The record of an LQG design, :class:`Design`: its gains, covariances and poles, what it
says of itself (:meth:`Design.to_dict`, :meth:`Design.summary`) and the formatting those
use; used by :mod:`equilibrist.control.design`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from equilibrist.control.analysis import (
    Margins,
    PoleInfo,
    Structure,
    controllability,
    loop_margins,
    observability,
    pole_table,
)
from equilibrist.control.interop import LOOP_CONTROLLERS, _loop_model
from equilibrist.control.kalman import DiscreteKalmanFilter
from equilibrist.control.lqg import Compensator, lqg_compensator
from equilibrist.errors import DesignError
from equilibrist.numeric.linear import LinearModel


@dataclass(frozen=True, eq=False)
class Design:
    """An LQG design: LQR state feedback, Kalman estimator and reference gain.

    Everything is in deviation coordinates about the plant's operating
    point ``plant.x0, plant.u0``: the control law is
    ``u = u0 - K (xhat - x0) + Kc (r - r0)`` with ``r0`` the tracked outputs
    at the operating point.

    Attributes
    ----------
    system_key:
        The system's registry key (``"cartpole"``, ``"gyroscope[euler=xyz]"``).
    params:
        The parameter values the design was made with.
    plant:
        Continuous linearization at the canonical point, with the chosen outputs.
    Q, R:
        LQR weights (``n x n``, ``m x m``).
    QN, RN, G:
        Process noise intensity (``k x k``) entering through ``G`` (``n x k``),
        and measurement noise intensity (``p x p``), in continuous time.
    rate:
        Sample rate [Hz] of a discrete design, None for a continuous one.
    discretization:
        ``"zoh"`` or ``"euler"`` (recorded also for a continuous design).
    kalman_form:
        ``"current"`` or ``"predictor"``: which discrete gain ``Kf`` is.
    discrete:
        The sampled plant (``Ad, Bd, C, D`` with ``dt``), None when continuous.
    K, S, poles:
        LQR gain (``u = -K x``), Riccati solution (cost ``x0' S x0``) and the
        closed-loop poles of the state feedback (``s``, or ``z`` when discrete).
    Kf:
        Estimator gain. Continuous: the ``lqe`` gain,
        ``xhat_dot = A xhat + B u + Kf (y - C xhat)``. Discrete ``"current"``:
        ``M = P C'(C P C' + Rd)^-1`` used as ``xhat = xpred + M (y - C xpred)``.
        Discrete ``"predictor"``: ``L = Ad M`` used as
        ``xhat+ = Ad xhat + Bd u + L (y - C xhat)``.
    P:
        Continuous: the ``lqe`` error covariance. Discrete: the steady-state
        a-priori (predicted) covariance.
    Kc, kc_note:
        Reference gain (``m x m``), or None with the reason in ``kc_note``
        (empty when ``Kc`` exists).
    Qd, Rd:
        Per-sample noise covariances of a discrete design, else None.
    tracked:
        The tracked outputs (the first ``m`` of the outputs).
    estimator_poles:
        Eigenvalues of ``A - Kf C`` (continuous) or ``Ad - L C`` (discrete,
        the same for both forms).
    notes:
        Choices made on the user's behalf (a process-noise floor).
    delay:
        The loop's delay in control periods the design compensates (0: none). With a
        delay, ``discrete`` is the sampled plant extended by the commands in flight
        (:func:`~equilibrist.control.discretize.with_input_delay`, states
        :attr:`model_state_names`) and ``K, S, poles, Kf, P, Qd, Kc, estimator_poles`` are
        that model's (:func:`~equilibrist.control.design_extended.delayed`); ``plant`` and the
        weights ``Q, R, QN, RN, G`` stay the plant's.
    velocity_filter, filtered:
        The cutoff [Hz] of the rig's low-pass of the measured rates *filtered* that the
        Kalman filter's model includes (0 and ``()``: none). With it, ``discrete`` is the
        sampled plant extended by the filter's last outputs
        (:func:`~equilibrist.control.discretize.with_velocity_filter`) and the gains are that
        model's (:func:`~equilibrist.control.design_extended.velocity_filtered`).
    """

    system_key: str
    params: Mapping[str, float]
    plant: LinearModel
    Q: np.ndarray
    R: np.ndarray
    QN: np.ndarray
    RN: np.ndarray
    G: np.ndarray
    rate: float | None
    discretization: str
    kalman_form: str
    discrete: LinearModel | None
    K: np.ndarray
    S: np.ndarray
    poles: np.ndarray
    Kf: np.ndarray
    P: np.ndarray
    Kc: np.ndarray | None
    kc_note: str
    Qd: np.ndarray | None
    Rd: np.ndarray | None
    tracked: tuple[str, ...]
    estimator_poles: np.ndarray
    notes: tuple[str, ...] = field(default=())
    delay: int = 0
    velocity_filter: float = 0.0
    filtered: tuple[str, ...] = ()

    def __repr__(self) -> str:  # one line; a notebook shows the tables (equilibrist.notebook)
        timebase = "continuous" if self.rate is None else f"{self.rate:g} Hz"
        timebase += f", delay {self.delay}" if self.delay else ""
        timebase += f", velocity filter {self.velocity_filter:g} Hz" if self.velocity_filter else ""
        slowest = max(info.time_constant for info in self.pole_table)
        return (f"Design({self.system_key}, LQG {timebase}, K={np.round(self.K, 4).tolist()}, "
                f"slowest pole tau={slowest:.3g} s)")

    # -- derived --------------------------------------------------------------------
    @property
    def dt(self) -> float | None:
        """Sample period ``1 / rate`` [s], None for a continuous design."""
        return None if self.rate is None else 1.0 / self.rate

    @property
    def is_discrete(self) -> bool:
        return self.rate is not None

    @property
    def model(self) -> LinearModel:
        """The model the gains were computed on: ``discrete`` if any, else ``plant``."""
        return self.discrete if self.discrete is not None else self.plant

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.plant.state_names

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.plant.input_names

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.plant.output_names

    @property
    def extended(self) -> bool:
        """Whether :attr:`model` extends the plant (a :attr:`delay`, a :attr:`velocity_filter`):
        its gains' columns are then more than the plant's states, and its controllers hold
        states of their own."""
        return self.model.n_states != self.plant.n_states

    @property
    def model_state_names(self) -> tuple[str, ...]:
        """The states of :attr:`model`, whose are the gains' columns: the plant's, then
        (with a :attr:`delay`) the commands in flight, oldest first."""
        return self.model.state_names

    @property
    def r0(self) -> np.ndarray:
        """The tracked outputs at the operating point (references are offsets from it)."""
        rows = [self.output_names.index(t) for t in self.tracked]
        return self.plant.y0[rows]

    @cached_property
    def controllability(self) -> Structure:
        m = self.model
        return controllability(m.A, m.B, state_names=m.state_names, discrete=m.is_discrete)

    @cached_property
    def observability(self) -> Structure:
        m = self.model
        return observability(m.A, m.C, state_names=m.state_names, discrete=m.is_discrete)

    @cached_property
    def open_loop_poles(self) -> np.ndarray:
        return _sorted(np.linalg.eigvals(self.model.A), self.is_discrete)

    @cached_property
    def pole_table(self) -> tuple[PoleInfo, ...]:
        """Closed-loop state-feedback poles with damping, frequency, time constant."""
        return pole_table(self.poles, dt=self.dt)

    @cached_property
    def estimator_pole_table(self) -> tuple[PoleInfo, ...]:
        return pole_table(self.estimator_poles, dt=self.dt)

    @cached_property
    def margins(self) -> Margins | None:
        """Margins of the LQG loop as implemented, broken at the plant input (single-input
        plants; else None).

        The loop is the compensator (:attr:`compensator`: the Kalman filter
        fed its own command, ``u = -K xhat``) in series with the plant, in
        the design's timebase (the discrete plant and the compensator's
        discrete form when the design is sampled): the system
        :func:`~equilibrist.control.interop.loop_at_input` returns. LQG has
        no guaranteed margins; these are usually well below
        :attr:`lqr_margins`.
        """
        return self._margins("lqg")

    @cached_property
    def lqr_margins(self) -> Margins | None:
        """Margins of the state feedback alone, ``L = K (sI - A)^-1 B`` (``z`` when sampled),
        broken at the plant input (single-input plants; else None): the loop of an LQR on the
        measured full state, not the LQG loop, which runs on the estimate. With a
        :attr:`delay`, the LQR's loop as it runs: the plant and its delay line in series with
        the controller whose record of the commands in flight is fed its own command
        (:func:`~equilibrist.control.interop.loop_at_input`)."""
        return self._margins("lqr")

    def margins_of(self, controller: str = "lqg") -> Margins | None:
        """The margins of *controller*'s loop as implemented: ``"lqg"`` (:attr:`margins`) or
        ``"lqr"`` (:attr:`lqr_margins`)."""
        if controller not in LOOP_CONTROLLERS:
            raise DesignError(
                f"the margins of controller {controller!r} are not a design's: expected "
                f"{' or '.join(LOOP_CONTROLLERS)}"
            )
        return self.margins if controller == "lqg" else self.lqr_margins

    def _margins(self, controller: str) -> Margins | None:
        if self.plant.n_inputs != 1:
            return None
        loop = _loop_model(self, controller=controller)
        return loop_margins(loop.A, loop.B, loop.C, dt=self.dt, D=float(loop.D[0, 0]))

    @cached_property
    def kalman_filter(self) -> DiscreteKalmanFilter:
        """The discrete Kalman filter of this design (discrete designs only)."""
        if self.discrete is None or self.Qd is None or self.Rd is None:
            raise DesignError("a continuous design has no discrete Kalman filter: give a rate")
        return DiscreteKalmanFilter.from_model(
            self.discrete, self.Qd, self.Rd, form=self.kalman_form
        )

    @cached_property
    def compensator(self) -> Compensator:
        """The LQG compensator with inputs ``(u, y, r)`` and output ``u``."""
        return lqg_compensator(
            self.model,
            self.K,
            self.Kf,
            self.Kc,
            tracked=self.tracked if self.Kc is not None else (),
            form=None if self.discrete is None else self.kalman_form,
        )

    # -- reports --------------------------------------------------------------------
    def to_dict(self, *, controller: str = "lqg") -> dict[str, object]:
        """Everything as plain JSON-ready values.

        Matrices are lists of rows; poles are lists of ``{"re", "im"}``
        objects (also when real); a non-finite number (an infinite time
        constant, an undefined damping ratio) is ``None``. ``margins`` are
        those of *controller*'s loop as implemented (:meth:`margins_of`:
        the LQG loop with its estimator by default), ``lqr_margins`` the
        state feedback's alone (the same for ``controller="lqr"``).
        """
        margins = self.margins_of(controller)
        disc = self.discrete
        out: dict[str, object] = {
            "system": self.system_key,
            "params": dict(self.params),
            "rate": self.rate,
            "dt": self.dt,
            "discretization": self.discretization,
            "kalman_form": self.kalman_form,
            "delay": self.delay,
            "velocity_filter": self.velocity_filter,
            "filtered": list(self.filtered),
            "states": list(self.state_names),
            "model_states": list(self.model_state_names),
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
            "tracked": list(self.tracked),
            "x0": self.plant.x0,
            "u0": self.plant.u0,
            "plant": {"A": self.plant.A, "B": self.plant.B, "C": self.plant.C, "D": self.plant.D},
            "discrete": None
            if disc is None
            else {
                "A": disc.A,
                "B": disc.B,
                "C": disc.C,
                "D": disc.D,
                "dt": disc.dt,
            },
            "Q": self.Q,
            "R": self.R,
            "QN": self.QN,
            "RN": self.RN,
            "G": self.G,
            "Qd": self.Qd,
            "Rd": self.Rd,
            "K": self.K,
            "S": self.S,
            "poles": _complex_list(self.poles),
            "Kf": self.Kf,
            "P": self.P,
            "estimator_poles": _complex_list(self.estimator_poles),
            "Kc": self.Kc,
            "kc_note": self.kc_note,
            "open_loop_poles": _complex_list(self.open_loop_poles),
            "pole_table": [p.to_dict() for p in self.pole_table],
            "estimator_pole_table": [p.to_dict() for p in self.estimator_pole_table],
            "margins": None if margins is None else margins.to_dict(),
            "lqr_margins": None if self.lqr_margins is None else self.lqr_margins.to_dict(),
            "controllability": self.controllability.to_dict(),
            "observability": self.observability.to_dict(),
            "notes": list(self.notes),
        }
        return {key: _plain(value) for key, value in out.items()}

    def summary(self, *, controller: str = "lqg") -> str:
        """A readable report of the design; its margins are *controller*'s loop's as
        implemented (:meth:`margins_of`), then the state feedback's alone for an LQG."""
        margins = self.margins_of(controller)
        kind = (
            f"discrete at {self.rate:g} Hz (dt = {self.dt:.4g} s, {self.discretization}, "
            f"{self.kalman_form} Kalman form)"
            if self.rate is not None
            else "continuous"
        )
        var = "z" if self.is_discrete else "s"
        states, inputs, outputs = self.state_names, self.input_names, self.output_names
        lines = [
            f"LQG design for {self.system_key}: {kind}",
            "operating point: "
            + ", ".join(f"{n} = {v:.4g}" for n, v in zip(states, self.plant.x0, strict=True))
            + "; "
            + ", ".join(f"{n} = {v:.4g}" for n, v in zip(inputs, self.plant.u0, strict=True)),
            f"measured outputs: {', '.join(outputs)}; tracked: {', '.join(self.tracked) or 'none'}",
            *([f"delay: {self.delay} control period(s), designed on the plant extended by the "
               f"commands in flight ({', '.join(self.model_state_names[len(states):])})"]
              if self.delay else []),
            *([f"velocity filter: the measured {', '.join(self.filtered)} read through the "
               f"rig's low-pass at {self.velocity_filter:g} Hz, the Kalman filter designed on "
               f"the plant extended by its states "
               f"({', '.join(self.model_state_names[len(states):])})"]
              if self.velocity_filter else []),
            "",
            "weights: Q = diag("
            + _numbers(np.diag(self.Q))
            + "), R = diag("
            + _numbers(np.diag(self.R))
            + ")",
            "noise:   QN = diag("
            + _numbers(np.diag(self.QN))
            + "), RN = diag("
            + _numbers(np.diag(self.RN))
            + ")",
            "",
            "LQR gain K (u = -K x):",
            _matrix(self.K, inputs, self.model_state_names),
            "",
            f"closed-loop poles ({var}):",
            _pole_lines(self.pole_table, self.is_discrete),
        ]
        if margins is not None and self.lqr_margins is not None:
            timebase = (
                f"discrete at {self.rate:g} Hz" if self.rate is not None else "continuous"
            )
            late = (f" and its line of {self.delay} command(s) in flight" if self.delay
                    else "")
            lqr_loop = (f"LQR: u = -Kx x - Ku b, its record b of the {self.delay} command(s) in "
                        f"flight fed its own command, in series with the plant{late}"
                        if self.delay else "LQR: u = -K x on the measured state")
            loop = (
                "LQG: the compensator, its Kalman filter fed its own command, in series with "
                f"the plant{late}"
                if controller == "lqg"
                else lqr_loop
            )
            lines += ["", f"loop broken at the input, as implemented ({loop}; {timebase}):"]
            lines += _margin_lines(margins)
            if controller == "lqg":
                alone = (f"the LQR with its record on the measured state, in series with the "
                         f"plant{late}" if self.delay else "LQR loop K (sI - A)^-1 B")
                lines += [
                    f"state feedback alone ({alone}, not the loop that runs: "
                    "LQG has no guaranteed margins):",
                    *_margin_lines(self.lqr_margins),
                ]
        gain_name = (
            "Kalman gain Kf"
            if not self.is_discrete
            else "Kalman gain M (current form)"
            if self.kalman_form == "current"
            else "Kalman gain L (predictor form)"
        )
        lines += [
            "",
            f"{gain_name}:",
            _matrix(self.Kf, self.model_state_names, outputs),
            "",
            f"estimator poles ({var}):",
            _pole_lines(self.estimator_pole_table, self.is_discrete),
            "",
        ]
        if self.Kc is not None:
            lines += [
                "reference gain Kc (u = -K x + Kc r):",
                _matrix(self.Kc, inputs, self.tracked),
            ]
        else:
            lines.append(f"no reference gain: {self.kc_note}")
        for note in self.notes:
            lines.append(f"note: {note}")
        return "\n".join(lines)


# -- formatting helpers ------------------------------------------------------------------


def _sorted(values: np.ndarray, discrete: bool) -> np.ndarray:
    vals = np.asarray(values, dtype=complex)
    key = np.abs(vals) if discrete else vals.real
    order = np.lexsort((vals.imag, key))
    return vals[order]


def _complex_list(values: np.ndarray) -> list[dict[str, float]]:
    return [{"re": float(v.real), "im": float(v.imag)} for v in np.asarray(values, dtype=complex)]


def _plain(obj: object) -> object:
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def _num(v: float) -> str:
    return f"{v:.4g}" if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "n/a")


def _margin_lines(mg: Margins) -> list[str]:
    return [
        f"  gain margins: stable for a loop gain scaled by x{_num(mg.gain_lower)} "
        f"({_num(mg.gain_lower_db)} dB, at {_num(mg.lower_crossover)} rad/s) "
        f"to x{_num(mg.gain_upper)} ({_num(mg.gain_upper_db)} dB, at "
        f"{_num(mg.upper_crossover)} rad/s)",
        f"  phase margin: {_num(mg.phase_margin)} deg at {_num(mg.gain_crossover)} rad/s",
        f"  min |1 + L|: {_num(mg.return_difference)}",
    ]


def _numbers(values: np.ndarray) -> str:
    return ", ".join(f"{v:.4g}" for v in values)


def _matrix(mat: np.ndarray, rows: Sequence[str], cols: Sequence[str], width: int = 12) -> str:
    label = max([len(r) for r in rows] + [1])
    out = [" " * (label + 2) + "".join(f"{c:>{width}}" for c in cols)]
    for r, row in zip(rows, np.atleast_2d(mat), strict=True):
        out.append(f"  {r:<{label}}" + "".join(f"{v:>{width}.5g}" for v in row))
    return "\n".join(out)


def _pole_lines(table: Sequence[PoleInfo], discrete: bool) -> str:
    out = []
    for p in table:
        value = (
            f"{p.pole.real:.5g} {'+' if p.pole.imag >= 0 else '-'} {abs(p.pole.imag):.4g}j"
            if p.pole.imag
            else f"{p.pole.real:.5g}"
        )
        extra = f"  |z| = {abs(p.pole):.5f}" if discrete else ""
        out.append(
            f"  {value:<26} wn = {_num(p.natural_frequency):>9} rad/s  zeta = "
            f"{_num(p.damping):>7}  tau = {_num(p.time_constant):>9} s{extra}"
        )
    return "\n".join(out)

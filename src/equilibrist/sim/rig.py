"""A rig's effects between the plant and the controller: what a real test bench adds.

The plant of a run is the system's model; a rig adds, at each control
period (the compiled core's ``eq_rig_measure`` and ``eq_rig_actuate``,
``native/core.c``):

* **encoders**: positions read in steps of ``encoder_step`` (``floor``),
  velocities computed as a rig computes them, by differencing the read
  positions over a period (0 at the first sample);
* **measurement delay**: the controller reads the measurement of ``d``
  samples before (the first sample's before that);
* **velocity noise**: white noise of standard deviation ``velocity_noise``
  on the measured velocities only;
* **velocity filter**: a first-order low-pass of the measured velocities,
  ``v_f += a (v - v_f)`` with ``a = 1 - exp(-2 pi f_c T)`` for the cutoff
  ``f_c`` [Hz];
* **actuation delay**: the motor receives the command of ``d`` samples
  before (the operating point's input before that);
* **torque response**: ``tau = tau_prev + k (tau_des - tau_prev)`` per
  period, ``tau_prev`` the torque that acted at the period before (the
  discrete form RealAIGym's benchmark uses, ``k`` its responsiveness:
  1 is immediate, below 1 a lag, above 1 an overshoot); or a first-order
  lag of time constant ``tc``, sampled exactly: ``k = 1 - exp(-T / tc)``;
* **torque noise**: white noise of standard deviation ``torque_noise`` on
  each input; the torque is then limited to the input's limits;
* **perturbations**: random Gaussian pulses of generalized force on any
  joint (actuated or passive), ``A exp(-(t - mu)^2 / (2 sigma^2))``, held
  over each period; the core adds ``M(q)^-1 tau`` to the accelerations, at
  every stage of the integrator. Their times are spread over the run as
  the benchmark spreads them (``perturbation_gap`` apart at least),
  widths and amplitudes drawn uniformly from their ranges, signs at random.
  With ``perturb_passive=False`` the pulses drawn for a joint no input drives
  are dropped (RealAIGym's plant multiplies the torques by its input matrix,
  which zeroes them: its perturbation family pushes the actuated joint only).

The noise is drawn from the run's generator (its seed), the pulses from a
generator seeded by the run's seed too: a seeded run is reproducible. The
controller is told the input it commanded (its ``update`` sees the
actuator's input as before); the result's ``applied`` input is the torque
that acted. Every effect is off by default, and a run without a rig is the
same bits as before rigs existed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim import layout

#: The spawn key's last word of a run's pulses' generator (beside its noise's).
_PULSE_KEY = 0x5EED_0F_F0


def _finite(value: object) -> bool:
    return (isinstance(value, int | float | np.integer | np.floating)
            and not isinstance(value, bool) and math.isfinite(float(value)))


@dataclass(frozen=True)
class Rig:
    """The effects of a rig (see the module); every one off by default."""

    torque_response: float | None = None
    torque_time_constant: float | None = None
    measurement_delay: int = 0
    measurement_delay_time: float = 0.0
    actuation_delay: int = 0
    actuation_delay_time: float = 0.0
    torque_noise: float = 0.0
    velocity_noise: float = 0.0
    encoder_step: float = 0.0
    velocity_filter: float = 0.0
    perturbations: int = 0
    perturbation_joints: tuple[str, ...] = ()
    perturbation_gap: float = 1.0
    perturbation_width: tuple[float, float] = (0.05, 0.1)
    perturbation_amplitude: tuple[float, float] = (0.5, 5.0)
    perturb_passive: bool = True

    @property
    def off(self) -> bool:
        """Whether the rig adds nothing."""
        return self == Rig()

    @property
    def draws(self) -> bool:
        """Whether a run draws random numbers for it (noise or pulses)."""
        return self.torque_noise > 0 or self.velocity_noise > 0 or self.perturbations > 0

    def problems(self, system: System, rate: float | None) -> list[str]:
        """Every problem with these effects on *system* at *rate*, one line each."""
        out: list[str] = []
        for name in ("torque_noise", "velocity_noise", "encoder_step", "velocity_filter",
                     "measurement_delay_time", "actuation_delay_time", "perturbation_gap"):
            value = getattr(self, name)
            if not _finite(value) or float(value) < 0:
                out.append(f"rig {name} = {value!r}: expected a finite number >= 0")
        for name in ("measurement_delay", "actuation_delay", "perturbations"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 0:
                out.append(f"rig {name} = {value!r}: expected a whole number >= 0")
        if self.torque_response is not None and self.torque_time_constant is not None:
            out.append("rig torque_response and torque_time_constant both given: expected one")
        for name in ("torque_response", "torque_time_constant"):
            value = getattr(self, name)
            if value is not None and (not _finite(value) or float(value) <= 0):
                out.append(f"rig {name} = {value!r}: expected a finite number > 0")
        for name in ("perturbation_width", "perturbation_amplitude"):
            pair = getattr(self, name)
            if (not isinstance(pair, tuple) or len(pair) != 2
                    or not all(_finite(v) and float(v) > 0 for v in pair) or pair[0] > pair[1]):
                out.append(f"rig {name} = {pair!r}: expected (low, high) with 0 < low <= high")
        needs_joints = (self.velocity_noise > 0 if _finite(self.velocity_noise) else True) \
            or self.encoder_step != 0 or self.velocity_filter != 0 or self.perturbations != 0
        nq = int(system.functions.N_Q)
        if needs_joints and (nq == 0 or system.n_states != 2 * nq):
            out.append(f"{system.key} has no joints' positions and velocities (a state [q, q_dot]): "
                       "the encoders, velocity noise and filter and perturbations need them")
        names = system.state_names[:nq]
        for joint in self.perturbation_joints:
            if joint not in names:
                out.append(f"rig perturbation joint {joint!r}: expected one of {', '.join(names)}")
        if rate is not None and not out:
            for name in ("measurement", "actuation"):
                try:
                    self.delay_samples(name, rate)
                except SimulationError as exc:
                    out.append(str(exc))
        return out

    def delay_samples(self, which: str, rate: float) -> int:
        """The *which* ("measurement" or "actuation") delay in samples at *rate*."""
        samples = int(getattr(self, f"{which}_delay"))
        seconds = float(getattr(self, f"{which}_delay_time"))
        periods = seconds * rate
        whole = round(periods)
        if abs(periods - whole) > 1e-9 * max(1.0, periods):
            raise SimulationError(
                f"rig {which} delay {seconds:g} s is {periods:g} control periods at {rate:g} Hz: "
                "expected a whole number of periods")
        return samples + int(whole)

    def response_k(self, rate: float) -> float | None:
        """The torque response's ``k`` per period, or None (immediate)."""
        if self.torque_time_constant is not None:
            return -math.expm1(-1.0 / (rate * float(self.torque_time_constant)))
        return None if self.torque_response is None else float(self.torque_response)

    def pack(self, system: System, rate: float, ny: int) -> tuple[np.ndarray, np.ndarray]:
        """The core's ``rig_i`` and ``rig_f`` (:data:`~equilibrist.sim.layout.RIG_I`, ``RIG_F``)."""
        k = self.response_k(rate)
        on = any((self.delay_samples("measurement", rate), self.delay_samples("actuation", rate),
                  k is not None, self.torque_noise > 0, self.velocity_noise > 0,
                  self.encoder_step > 0, self.velocity_filter > 0))
        rig_i = layout.RIG_I.pack(
            np.int64, on=int(on), meas_delay=self.delay_samples("measurement", rate),
            act_delay=self.delay_samples("actuation", rate), response=int(k is not None),
            encoder=int(self.encoder_step > 0), filter=int(self.velocity_filter > 0),
            nq=int(system.functions.N_Q))
        rig_f = layout.RIG_F.pack(
            response_k=1.0 if k is None else k, torque_sigma=float(self.torque_noise),
            vel_sigma=float(self.velocity_noise), encoder_step=float(self.encoder_step),
            filter_a=-math.expm1(-2.0 * math.pi * float(self.velocity_filter) / rate))
        return rig_i, rig_f

    def state_len(self, system: System, rate: float, ny: int) -> int:
        """Doubles of one run's rig state."""
        return layout.rig_state_len(system.n_inputs, ny, int(system.functions.N_Q),
                                    self.delay_samples("actuation", rate),
                                    self.delay_samples("measurement", rate))

    def pulses(self, system: System, rate: float, n_samples: int,
               seq: np.random.SeedSequence) -> tuple[np.ndarray, dict[str, object]]:
        """One run's perturbations: the generalized forces ``(n_samples, nq)`` held over each
        period, and their description (joints, times, widths, amplitudes)."""
        nq = int(system.functions.N_Q)
        names = system.state_names[:nq]
        joints = [names.index(j) for j in (self.perturbation_joints or names)]
        per = int(self.perturbations)
        count = len(joints) * per
        duration = n_samples / rate
        gap = float(self.perturbation_gap)
        wiggle = (duration - (count + 1) * gap) / count
        if wiggle < 0:
            raise SimulationError(
                f"rig: {count} perturbations at least {gap:g} s apart do not fit in "
                f"{duration:g} s: expected fewer, a smaller perturbation_gap or a longer run")
        rng = np.random.default_rng(
            np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, _PULSE_KEY)))
        mu = np.cumsum(gap + rng.random(count) * wiggle)
        rng.shuffle(mu)
        mu = mu.reshape(len(joints), per)
        lo, hi = (float(v) for v in self.perturbation_width)
        sigma = lo + rng.random((len(joints), per)) * (hi - lo)
        alo, ahi = (float(v) for v in self.perturbation_amplitude)
        amp = rng.uniform(-(ahi - alo), ahi - alo, size=(len(joints), per))
        amp += alo * np.sign(amp)
        t = np.arange(n_samples) / rate
        forces = np.zeros((n_samples, nq))
        for row, joint in enumerate(joints):
            for i in range(per):
                forces[:, joint] += amp[row, i] * np.exp(
                    -np.power(t - mu[row, i], 2.0) / (2 * sigma[row, i] ** 2.0))
        if not self.perturb_passive:  # the drawn pulses of joints without an input dropped
            forces[:, ~actuated(system)] = 0.0
        described = {"joints": [names[j] for j in joints], "times": mu.tolist(),
                     "widths": sigma.tolist(), "amplitudes": amp.tolist()}
        return np.ascontiguousarray(forces), described

    def describe(self) -> dict[str, object]:
        """The effects that are on, as JSON-able data."""
        default = Rig()
        out: dict[str, object] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value != getattr(default, f.name):
                out[f.name] = list(value) if isinstance(value, tuple) else value
        if self.perturbations == 0:
            for name in ("perturbation_joints", "perturbation_gap", "perturbation_width",
                         "perturbation_amplitude"):
                out.pop(name, None)
        return out


def actuated(system: System) -> np.ndarray:
    """Per coordinate, whether an input exerts a generalized force on it (``M B`` at the
    operating point, ``B`` the inputs' columns of the accelerations)."""
    nq = int(system.functions.N_Q)
    point = system.operating_point()
    _a, b = system.jacobians(point.x, point.u)
    mass = np.zeros((nq, nq))
    system.functions.mass_matrix(np.asarray(point.x, dtype=float), system.p, mass)
    forces = np.abs(mass @ np.asarray(b)[nq:, :])
    return np.asarray(forces.max(axis=1) > 1e-9 * max(1.0, float(forces.max())))


def check(rig: object) -> Rig | None:
    """*rig* as a :class:`Rig` (None, or one that adds nothing: None)."""
    if rig is None:
        return None
    if not isinstance(rig, Rig):
        raise SimulationError(f"rig = {rig!r}: expected an equilibrist.sim.rig.Rig or None")
    return None if rig.off else rig


__all__ = ["Rig", "actuated", "check"]

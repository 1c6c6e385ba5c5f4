"""The settings of a run, validated, with the compiled core's packed arrays
(:class:`Setup`, made by :func:`equilibrist.sim.setup.build`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.control.python_controller import PythonController
from equilibrist.numeric.system import System
from equilibrist.sim import events as ev
from equilibrist.sim import integrators, layout
from equilibrist.sim.noise import Noise
from equilibrist.sim.rig import Rig

if TYPE_CHECKING:
    from equilibrist.sim.signals import Signal


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything a run needs, validated, with the core's packed arrays."""

    system: System
    controller: LinearController | NonlinearController | PythonController
    compiled: bool
    estimates: bool
    description: dict[str, object]
    cp: np.ndarray
    z0: np.ndarray
    rate: float
    h: float
    n_sub: int
    n_samples: int
    integrator: str
    rtol: float
    atol: float
    plant: str
    delay: bool
    x0: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    outputs: tuple[str, ...]
    c_idx: np.ndarray
    tracked: tuple[str, ...]
    r_op: np.ndarray
    times: np.ndarray
    ref: np.ndarray
    uff: np.ndarray
    op: np.ndarray
    lv: np.ndarray
    lw: np.ndarray
    noise: Noise | None
    events: tuple[ev.Event, ...]
    change_steps: np.ndarray
    change_values: tuple[dict[str, float], ...]
    kicks: np.ndarray
    kick_value: np.ndarray
    pulses: np.ndarray
    pulse_value: np.ndarray
    region: np.ndarray
    region_spec: dict[str, tuple[float, float]]
    duration: float
    reference: Signal | None
    excitation: Signal | None = None
    rig: Rig | None = None

    @property
    def n_rows(self) -> int:
        return self.n_samples + 1

    @property
    def nonlinear(self) -> NonlinearController | None:
        """The nonlinear controller whose kernel runs this setup, if any."""
        return self.controller if isinstance(self.controller, NonlinearController) else None

    def iopts(self, *, record: bool = True, accumulate: bool = True) -> np.ndarray:
        """The core's integer options: *record* the trajectory, *accumulate* the peaks
        and sums of a batch's outcomes (a single run's come from its trajectory)."""
        return layout.IOPTS.pack(
            np.int64, n_samples=self.n_samples, record=int(record), delay=int(self.delay),
            n_sub=self.n_sub, estimates=int(self.estimates), accumulate=int(accumulate),
            integrator=integrators.number("linear" if self.plant == "linear" else self.integrator),
        )

    def rig_arrays(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The core's ``rig_i`` and ``rig_f``, or (None, None) without a rig."""
        if self.rig is None:
            return None, None
        return self.rig.pack(self.system, self.rate, len(self.outputs))

    def rig_state(self) -> np.ndarray | None:
        """A fresh rig state for one run (None without a rig)."""
        if self.rig is None:
            return None
        return np.zeros(self.rig.state_len(self.system, self.rate, len(self.outputs)))

    def rig_forces(self, seq: np.random.SeedSequence | None
                   ) -> tuple[np.ndarray | None, dict[str, object] | None]:
        """One run's perturbations (generalized forces per sample) and their description."""
        if self.rig is None or self.rig.perturbations == 0 or seq is None:
            return None, None
        return self.rig.pulses(self.system, self.rate, self.n_rows, seq)

    @property
    def fopts(self) -> np.ndarray:
        return layout.FOPTS.pack(h=self.h, rtol=self.rtol, atol=self.atol, rate=self.rate)

    @property
    def sizes(self) -> dict[str, int]:
        return {"n": self.x_op.shape[0], "m": self.u_op.shape[0], "ny": len(self.outputs)}

    @property
    def rec_cols(self) -> np.ndarray:
        return layout.RECORD.offsets(n=self.x_op.shape[0], m=self.u_op.shape[0],
                                     ny=len(self.outputs))

    @property
    def acc_cols(self) -> np.ndarray:
        return layout.ACC.offsets(n=self.x_op.shape[0], m=self.u_op.shape[0],
                                  ny=len(self.outputs))

    @property
    def record_width(self) -> int:
        return layout.RECORD.width(**self.sizes)

    @property
    def acc_len(self) -> int:
        return layout.ACC.width(**self.sizes)

    def p_sets(self, base: np.ndarray) -> np.ndarray:
        """The parameter sets of the run from parameter vector(s) *base*: ``(..., n_sets, n_p)``.

        Each change sets its parameters from its time on, on top of the
        parameters before it.
        """
        base = np.asarray(base, dtype=float)
        if not self.change_values:
            return np.ascontiguousarray(base[..., None, :])
        names = self.system.spec.parameter_names
        sets = [base]
        for values in self.change_values:
            nxt = sets[-1].copy()
            for name, v in values.items():
                nxt[..., names.index(name)] = v
            sets.append(nxt)
        return np.ascontiguousarray(np.stack(sets, axis=-2))

    @property
    def p_switch(self) -> np.ndarray:
        return np.concatenate([[0], self.change_steps]).astype(np.int64)

    def linear_blocks(self, p_sets: np.ndarray) -> np.ndarray:
        """``[Phi | E | Gamma | f0]`` per parameter set (``(n_sets, n, 2n+m+1)``), or empty."""
        n, m = self.system.n_states, self.system.n_inputs
        if self.plant != "linear":
            return np.zeros((p_sets.shape[0], 0, 0))
        from scipy.linalg import expm

        names = self.system.spec.parameter_names
        out = np.zeros((p_sets.shape[0], n, 2 * n + m + 1))
        for j, pv in enumerate(p_sets):
            sysj = self.system.with_params(**dict(zip(names, pv.tolist(), strict=True)))
            A, B = sysj.jacobians(self.x_op, self.u_op)
            f0 = sysj.f(self.x_op, self.u_op)
            aug = np.zeros((2 * n, 2 * n))
            aug[:n, :n] = A
            aug[:n, n:] = np.eye(n)
            big = expm(aug * self.h)
            phi, ex = big[:n, :n], big[:n, n:]
            out[j, :, :n] = phi
            out[j, :, n : 2 * n] = ex
            out[j, :, 2 * n : 2 * n + m] = ex @ B
            out[j, :, 2 * n + m] = f0
        return out

    def describe(self) -> dict[str, object]:
        """The settings as JSON-able data (recorded with every result)."""
        return {
            "system": self.system.key,
            "controller": self.description,
            "duration": self.duration,
            "n_samples": self.n_samples,
            "rate": self.rate,
            "physics_step": self.h,
            "substeps": self.n_sub,
            "integrator": self.integrator,
            "rtol": self.rtol,
            "atol": self.atol,
            "plant": self.plant,
            "delay": self.delay,
            "x0": self.x0.tolist(),
            "outputs": list(self.outputs),
            "noise": None if self.noise is None else self.noise.describe(),
            "reference": None if self.reference is None else self.reference.describe(),
            "tracked": list(self.tracked),
            "events": ev.describe(self.events),
            "region": {k: [lo, hi] for k, (lo, hi) in self.region_spec.items()},
            "excitation": None if self.excitation is None else self.excitation.describe(),
        } | ({} if self.rig is None else {"rig": self.rig.describe()})

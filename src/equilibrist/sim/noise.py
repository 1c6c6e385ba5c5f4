"""Process and measurement noise, and the seeds that make it reproducible.

The plant is disturbed by continuous white noise ``w`` of intensity
(power spectral density) ``QN`` entering through ``G``:
``x_dot = f(x, u) + G w``. The simulator holds ``w`` constant over each
physics step ``h`` with covariance ``QN / h`` (so its integral over a step
has covariance ``G QN G' h``, the continuous noise's, and the sampled plant
sees the design's ``Q_d`` in the limit of small steps). The sensors add
white noise of covariance ``R`` (per sample) to each measured output.

With a design from the control layer both come from it: ``G`` and ``QN``,
and ``R = R_d`` (``RN / T``), the covariances the Kalman filter assumes.

Randomness comes only from a seed: an integer or a
:class:`numpy.random.SeedSequence` (batches give run ``i`` the ``i``-th
child of their seed's sequence). The seed fixes the four 64-bit words of
the compiled core's xoshiro256** generator.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from equilibrist.control.design_record import Design
from equilibrist.errors import DimensionError, SimulationError


def _matrix(value: object, shape: tuple[int, int], what: str) -> np.ndarray:
    arr = np.atleast_2d(np.asarray(value, dtype=float))
    if arr.shape == (1, shape[0]) and shape[0] == shape[1] and shape[0] > 1:
        arr = np.diag(arr[0])  # a diagonal given as a vector
    if arr.shape != shape:
        raise DimensionError(f"{what} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise SimulationError(f"{what} has a value that is not finite")
    return arr


def _cholesky(a: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor of *a*, or None when *a* is not positive definite.

    Written out (row by row, each sum in index order, IEEE ``sqrt``) rather
    than LAPACK's, whose BLAS kernel (and so its rounding) depends on the
    CPU: the noise the core draws is the same on every machine.
    """
    n = a.shape[0]
    low = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = float(a[i, j])
            for k in range(j):
                s -= float(low[i, k]) * float(low[j, k])
            if i == j:
                if not s > 0.0:
                    return None
                low[i, i] = math.sqrt(s)
            else:
                low[i, j] = s / float(low[j, j])
    return low


def square_root(cov: np.ndarray, what: str) -> np.ndarray:
    """``L`` with ``L L' = cov`` for a symmetric positive semi-definite *cov*."""
    cov = np.asarray(cov, dtype=float)
    if cov.size == 0:
        return np.zeros(cov.shape)
    scale = float(np.abs(cov).max())
    if float(np.abs(cov - cov.T).max()) > 1e-9 * scale:
        raise SimulationError(f"{what} is not symmetric")
    sym = (cov + cov.T) / 2
    root = _cholesky(sym)
    if root is not None:
        return root
    # Semi-definite (or not at all): LAPACK's eigenvectors, whose last bits depend on
    # the BLAS kernel the CPU selects (docs/reproducibility.md).
    vals, vecs = np.linalg.eigh(sym)
    if vals.min() < -1e-10 * max(1.0, float(abs(vals).max())):
        raise SimulationError(
            f"{what} is not positive semi-definite (eigenvalue {vals.min():.3g})"
        ) from None
    factor: np.ndarray = vecs * np.sqrt(np.clip(vals, 0.0, None))
    return factor


@dataclass(frozen=True, eq=False)
class Noise:
    """Noise of a simulated rig.

    Attributes
    ----------
    process_gain : ndarray, shape (n_states, n_w)
        ``G``: how each noise channel enters the state rates.
    process_intensity : ndarray, shape (n_w, n_w)
        ``QN``: intensity (power spectral density) of the process noise.
    measurement_covariance : ndarray, shape (n_outputs, n_outputs)
        Covariance of the sensor noise added to each sample of ``outputs``.
    outputs : tuple of str
        The measured states the measurement covariance refers to.
    """

    process_gain: np.ndarray
    process_intensity: np.ndarray
    measurement_covariance: np.ndarray
    outputs: tuple[str, ...]

    def __post_init__(self) -> None:
        g = np.atleast_2d(np.asarray(self.process_gain, dtype=float))
        nw = g.shape[1]
        q = _matrix(self.process_intensity, (nw, nw), "the process noise intensity")
        ny = len(self.outputs)
        r = _matrix(self.measurement_covariance, (ny, ny), "the measurement noise covariance")
        if not np.all(np.isfinite(g)):
            raise SimulationError("the process noise gain has a value that is not finite")
        for a in (g, q, r):
            a.setflags(write=False)
        square_root(q, "the process noise intensity")  # refuse a bad one at once
        square_root(r, "the measurement noise covariance")
        object.__setattr__(self, "process_gain", g)
        object.__setattr__(self, "process_intensity", q)
        object.__setattr__(self, "measurement_covariance", r)
        object.__setattr__(self, "outputs", tuple(self.outputs))

    @classmethod
    def from_design(cls, design: Design, *, rate: float | None = None) -> Noise:
        """The covariances a design assumed: ``G``, ``QN`` and ``R_d``.

        A continuous design has no ``R_d``: then ``R = RN / T`` with ``T = 1 /
        rate`` the simulation's control period (*rate* is required then).
        """
        if not isinstance(design, Design):
            raise SimulationError(f"design: expected a Design (equilibrist.control.design.design), "
                                  f"got {type(design).__name__}")
        plant = design.plant
        rd = design.Rd
        if rd is None:
            if rate is None:
                raise SimulationError(
                    "a continuous design has no per-sample measurement noise covariance: "
                    "give the simulation's rate (Noise.from_design(design, rate=...))"
                )
            rd = np.asarray(design.RN, dtype=float) * float(rate)
        return cls(
            process_gain=np.asarray(design.G, dtype=float),
            process_intensity=np.asarray(design.QN, dtype=float),
            measurement_covariance=np.asarray(rd, dtype=float),
            outputs=tuple(plant.output_names),
        )

    @classmethod
    def from_spec(cls, system: object, *, outputs: Sequence[str] | None = None,
                  rate: float) -> Noise:
        """Noise from the system's catalogue entry, without a design.

        The sensor standard deviations ``sensor_noise`` give ``R`` directly;
        the process-noise standard deviations ``process_noise`` (on state
        rates) are read as what the rates would show over one control
        period, so ``QN = sigma^2 / rate``.
        """
        spec = system.spec  # type: ignore[attr-defined]
        names = tuple(system.state_names)  # type: ignore[attr-defined]
        outs = tuple(outputs) if outputs is not None else (tuple(spec.outputs) or names)
        sigma_y = np.array([float(spec.sensor_noise.get(o, 0.0)) for o in outs])
        rows = [s for s in names if s in spec.process_noise]
        g = np.zeros((len(names), len(rows)))
        for j, s in enumerate(rows):
            g[names.index(s), j] = 1.0
        qn = np.diag([float(spec.process_noise[s]) ** 2 / rate for s in rows])
        return cls(g, qn.reshape(len(rows), len(rows)), np.diag(sigma_y**2), outs)

    @cached_property
    def process_root(self) -> np.ndarray:
        """``L`` with ``L L' = QN``."""
        return square_root(self.process_intensity, "the process noise intensity")

    def describe(self) -> dict[str, object]:
        return {
            "process_gain": self.process_gain.tolist(),
            "process_intensity": self.process_intensity.tolist(),
            "measurement_covariance": self.measurement_covariance.tolist(),
            "outputs": list(self.outputs),
        }


SeedLike = int | np.random.SeedSequence | None


def seed_sequence(seed: SeedLike) -> np.random.SeedSequence:
    """A :class:`~numpy.random.SeedSequence` from *seed* (fresh entropy for None)."""
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if seed is None:
        return np.random.SeedSequence()
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise SimulationError(f"seed {seed!r} must be a non-negative integer")
    return np.random.SeedSequence(int(seed))


def generator_state(seq: np.random.SeedSequence) -> np.ndarray:
    """The four words of the core's generator for *seq* (never all zero)."""
    state = seq.generate_state(4, np.uint64)
    if not state.any():  # pragma: no cover - probability 2**-256
        state[0] = np.uint64(1)
    return state


def describe_seed(seq: np.random.SeedSequence) -> dict[str, object]:
    """``{"entropy": ..., "spawn_key": [...]}``: enough to rebuild *seq*."""
    entropy = seq.entropy
    if isinstance(entropy, np.ndarray | list | tuple):
        entropy = [int(e) for e in entropy]
    else:
        entropy = int(entropy)  # type: ignore[arg-type]
    return {"entropy": entropy, "spawn_key": [int(k) for k in seq.spawn_key]}


def seed_from_description(desc: dict[str, object]) -> np.random.SeedSequence:
    return np.random.SeedSequence(desc["entropy"], spawn_key=tuple(desc["spawn_key"]))  # type: ignore[arg-type]

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
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control import _checks
from equilibrist.control.analysis import (
    Margins,
    PoleInfo,
    Structure,
    _pbh_modes,
    controllability,
    describe_modes,
    loop_margins,
    observability,
    pole_table,
)
from equilibrist.control.discretize import METHODS, discrete_noise, discretize
from equilibrist.control.kalman import FORMS, DiscreteKalmanFilter
from equilibrist.control.lqg import Compensator, lqg_compensator
from equilibrist.control.reference import discrete_reference_gain, reference_gain
from equilibrist.control.riccati import (
    _boundary_modes,
    _sqrt_psd,
    current_gain,
    dlqe,
    dlqr,
    lqe,
    lqr,
)
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.linear import LinearModel

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

# Floor of the default process noise on states the spec gives none, as a
# fraction of the state's design scale (used only when needed; see above).
NOISE_FLOOR = 1e-3


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
        """Margins of the loop broken at the input (single-input plants; else None)."""
        if self.plant.n_inputs != 1:
            return None
        m = self.model
        return loop_margins(m.A, m.B, self.K, dt=self.dt)

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
    def to_dict(self) -> dict[str, Any]:
        """Everything as plain JSON-ready values.

        Matrices are lists of rows; poles are lists of ``{"re", "im"}``
        objects (also when real); a non-finite number (an infinite time
        constant, an undefined damping ratio) is ``None``.
        """
        disc = self.discrete
        out: dict[str, Any] = {
            "system": self.system_key,
            "params": dict(self.params),
            "rate": self.rate,
            "dt": self.dt,
            "discretization": self.discretization,
            "kalman_form": self.kalman_form,
            "states": list(self.state_names),
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
            "margins": None if self.margins is None else self.margins.to_dict(),
            "controllability": self.controllability.to_dict(),
            "observability": self.observability.to_dict(),
            "notes": list(self.notes),
        }
        plain: dict[str, Any] = _plain(out)
        return plain

    def summary(self) -> str:
        """A readable report of the design."""
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
            _matrix(self.K, inputs, states),
            "",
            f"closed-loop poles ({var}):",
            _pole_lines(self.pole_table, self.is_discrete),
        ]
        if self.margins is not None:
            mg = self.margins
            lines += [
                "",
                "loop broken at the input:",
                f"  gain margins: stable for a loop gain scaled by x{_num(mg.gain_lower)} "
                f"({_num(mg.gain_lower_db)} dB, at {_num(mg.lower_crossover)} rad/s) "
                f"to x{_num(mg.gain_upper)} ({_num(mg.gain_upper_db)} dB, at "
                f"{_num(mg.upper_crossover)} rad/s)",
                f"  phase margin: {_num(mg.phase_margin)} deg at {_num(mg.gain_crossover)} rad/s",
                f"  min |1 + L|: {_num(mg.return_difference)}",
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
            _matrix(self.Kf, states, outputs),
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


def _plain(obj: Any) -> Any:
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


# -- argument handling ---------------------------------------------------------------------


def _weight(
    value: object, name: str, labels: Sequence[str], *, definite: bool, problems: list[str]
) -> np.ndarray:
    """A vector (the diagonal) or a square matrix over *labels*; sign problems collected."""
    n = len(labels)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise DimensionError(f"{name} must be numbers, got {value!r}") from None
    if arr.ndim == 0 and n == 1:
        arr = arr.reshape(1)
    if arr.ndim == 1:
        if arr.size != n:
            raise DimensionError(
                f"{name} has {arr.size} values, expected {n} (one per {', '.join(labels)})"
            )
        if not np.all(np.isfinite(arr)):
            raise DesignError(f"{name} has a value that is not a finite number")
        for label, v in zip(labels, arr, strict=True):
            if definite and not v > 0:
                problems.append(f"{name} for {label} is {v:g}: expected > 0")
            elif not definite and v < 0:
                problems.append(f"{name} for {label} is {v:g}: expected >= 0")
        return np.diag(arr)
    mat = _checks.matrix(arr, name, (n, n), f"one row and column per {', '.join(labels)}")
    problems.extend(_checks.weight_problems(mat, name, definite=definite))
    return mat


def _bryson(system: System, names: Sequence[str], missing: list[str]) -> np.ndarray:
    scales = system.spec.design_scales
    values = []
    for n in names:
        s = scales.get(n)
        if s is None or not s > 0:
            missing.append(n)
            values.append(1.0)
        else:
            values.append(1.0 / float(s) ** 2)
    return np.diag(values)


def _default_process_noise(
    system: System, plant: LinearModel
) -> tuple[np.ndarray, tuple[str, ...]]:
    spec, states = system.spec, plant.state_names
    if not spec.process_noise:
        raise DesignError(
            f"{system.key} gives no process noise in its spec: give qn "
            f"(one value per state: {', '.join(states)})"
        )
    unknown = [k for k in spec.process_noise if k not in states]
    if unknown:
        raise DesignError(
            f"{system.key}'s process noise names {', '.join(unknown)}, which are not states "
            f"({', '.join(states)}): give qn"
        )
    sigma = np.array([float(spec.process_noise.get(s, 0.0)) for s in states])
    QN = np.diag(sigma**2)
    scale = float(np.linalg.norm(plant.A, 2)) if plant.n_states else 1.0
    hidden = _boundary_modes(_pbh_modes(plant.A, _sqrt_psd(QN), states, False), False, scale)
    if not hidden:
        return QN, ()
    quiet = [s for s, v in zip(states, sigma, strict=True) if v == 0]
    involved = {s for mode in hidden for s in mode.states}
    if any(s in involved for s in quiet):
        quiet = [s for s in quiet if s in involved]
    missing = [s for s in quiet if not spec.design_scales.get(s, 0) > 0]
    if missing:
        raise DesignError(
            f"{system.key}'s process noise leaves the marginal mode(s) {describe_modes(hidden)} "
            f"unexcited and there is no design scale for {', '.join(missing)} to set a floor: "
            f"give qn"
        )
    for s in quiet:
        i = states.index(s)
        QN[i, i] = (NOISE_FLOOR * float(spec.design_scales[s])) ** 2
    still = _boundary_modes(_pbh_modes(plant.A, _sqrt_psd(QN), states, False), False, scale)
    if still:
        raise DesignError(
            f"{system.key}'s process noise leaves the marginal mode(s) {describe_modes(still)} "
            f"unexcited: give qn"
        )
    note = (
        f"process noise floor (1e-3 x design scale)^2 added on {', '.join(quiet)}: the spec's "
        f"process noise leaves the marginal mode(s) {describe_modes(hidden)} unexcited, and the "
        f"Kalman Riccati equation would have no stabilizing solution"
    )
    return QN, (note,)


# The fastest sample rate a design accepts [Hz].
MAX_RATE = 1e6


# -- designs kept on disk: a run that needs one made before neither redoes it nor imports scipy
#: The sources a design's numbers come from (a change to any makes new keys).
_DESIGN_SOURCES = ("design", "analysis", "discretize", "kalman", "lqg", "reference", "riccati",
                   "_checks")
_SOURCES_DIGEST: list[str] = []


def _sources_digest() -> str:
    if not _SOURCES_DIGEST:
        import hashlib
        import importlib.metadata
        from pathlib import Path

        h = hashlib.sha256()
        here = Path(__file__).parent
        for name in _DESIGN_SOURCES:
            h.update((here / f"{name}.py").read_bytes())
        h.update((here.parent / "numeric" / "linear.py").read_bytes())
        for dist in ("numpy", "scipy"):
            h.update(importlib.metadata.version(dist).encode())
        _SOURCES_DIGEST.append(h.hexdigest())
    return _SOURCES_DIGEST[0]


def _cache_key(system: System, args: tuple[object, ...]) -> str | None:
    """The file name of a design of *system* with *args* (None when they do not pickle:
    an argument the design will refuse anyway)."""
    import hashlib
    import os
    import pickle

    from equilibrist.numeric.system import System as _System

    if not isinstance(system, _System):
        return None
    try:
        norm = tuple(sorted(a.items()) if isinstance(a, Mapping) else a for a in args)
        blob = pickle.dumps((system.key, system.compiled.module_path.name, system.digest,
                             system.spec, tuple(sorted(system.params.items())), norm),
                            protocol=4)
    except Exception:  # an argument that does not pickle: no cache for it
        return None
    h = hashlib.sha256(blob)
    h.update(_sources_digest().encode())
    # The BLAS kernel OpenBLAS is told to use changes the design's last bits.
    h.update(os.environ.get("OPENBLAS_CORETYPE", "").encode())
    return h.hexdigest()[:24]


def _design_folder() -> Any:
    from equilibrist.numeric.cache import cache_dir

    folder = cache_dir() / "designs"
    folder.mkdir(exist_ok=True)
    return folder


def _kept_on_disk(make: Callable[..., Design]) -> Callable[..., Design]:
    """*make* (``design``), its results kept on disk under the hash of its arguments."""
    import functools
    import inspect

    signature = inspect.signature(make)

    @functools.wraps(make)
    def design(system: System, **options: Any) -> Design:
        try:
            bound = signature.bind(system, **options)
        except TypeError:
            return make(system, **options)  # as Python would refuse it
        bound.apply_defaults()
        args = tuple(v for k, v in bound.arguments.items() if k != "system")
        key = _cache_key(system, args)
        if key is not None:
            known = _cached(key, system)
            if known is not None:
                return known
        made = make(system, **options)
        if key is not None:
            _keep(key, made)
        return made

    return design


def read_only(values: dict[str, float]) -> types.MappingProxyType[str, float]:
    """A read-only view of *values* (how a pickled design's parameters come back)."""
    return types.MappingProxyType(values)


def _register_pickling() -> None:
    import copyreg

    copyreg.pickle(types.MappingProxyType, lambda m: (read_only, (dict(m),)))


# A design's parameters are a read-only mapping: pickled as a dict whichever way the design
# came (made here or read from the cache folder), so a controller holding one goes to a
# batch's worker processes.
_register_pickling()


def _cached(key: str, system: System) -> Design | None:
    import pickle

    path = _design_folder() / f"{key}.pkl"
    try:
        with path.open("rb") as fh:
            known = pickle.load(fh)  # our own cache folder, only we can write it
    except Exception:  # missing or damaged: designed again
        return None
    if not isinstance(known, Design) or known.system_key != system.key:
        return None
    return known


def _keep(key: str, made: Design) -> None:
    import os
    import pickle
    import tempfile

    _register_pickling()
    folder = _design_folder()
    try:
        blob = pickle.dumps(made, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # something in it does not pickle: simply not kept
        return
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f"{key}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.replace(tmp, folder / f"{key}.pkl")
    except BaseException:
        os.unlink(tmp)
        raise


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
) -> Design:
    """Design LQR, Kalman filter and reference gain for *system* at its canonical point.

    With *at*, the design is made at another operating point: the
    equilibrium with the given states (``{"theta": math.pi}``), its other
    components solved as for the canonical one.

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
    _checks.raise_if(problems)
    if system.n_inputs == 0:
        raise DesignError(f"{system.key} has no input: there is no controller to design")

    names = tuple(system.output_names if outputs is None else outputs)
    if not names:
        raise DesignError("no measured outputs: the estimator needs at least one")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DesignError(f"outputs lists {', '.join(repeated)} more than once")
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
    states, inputs = plant.state_names, plant.input_names
    n, m = plant.n_states, plant.n_inputs
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

    # Weights: defaults from the spec, or the user's; every problem at once.
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
        Gm = _checks.with_rows(G, "G", n, "one per state")
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
    _checks.raise_if(problems)

    tracked = names[:m] if len(names) >= m else ()
    Cr = plant.C[:m] if tracked else None
    Kc: np.ndarray | None = None
    kc_note = ""
    if rate_hz is None:
        K, S, E = lqr(plant.A, plant.B, Q, R, state_names=states)
        Kf, P, Ef = lqe(plant.A, Gm, plant.C, QN, RN, state_names=states, output_names=names)
        disc, Qd, Rd = None, None, None
        if Cr is not None:
            try:
                Kc = reference_gain(
                    plant.A, plant.B, Cr, K, tracked_names=tracked, input_names=inputs
                )
            except DesignError as exc:
                kc_note = str(exc)
    else:
        dt = 1.0 / rate_hz
        disc = discretize(plant, dt, method=discretization)
        Qd, Rd = discrete_noise(plant.A, Gm, QN, RN, dt, method=discretization)
        K, S, E = dlqr(disc.A, disc.B, Q, R, state_names=states)
        L, P, Ef = dlqe(disc.A, np.eye(n), disc.C, Qd, Rd, state_names=states, output_names=names)
        Kf = current_gain(P, disc.C, Rd) if kalman_form == "current" else L
        if Cr is not None:
            try:
                Kc = discrete_reference_gain(
                    disc.A, disc.B, Cr, K, tracked_names=tracked, input_names=inputs
                )
            except DesignError as exc:
                kc_note = str(exc)
    if Cr is None:
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
        notes=notes,
    )

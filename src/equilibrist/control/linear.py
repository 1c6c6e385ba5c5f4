"""The linear controller: one discrete state-space form in deviation coordinates
(:class:`LinearController`, see :mod:`equilibrist.control.controller`) and its Python
runtime (:class:`LinearRuntime`); used by :mod:`equilibrist.control.controller`.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.python_controller import PythonControllerBase
from equilibrist.errors import ControllerError, DesignError, DimensionError
from equilibrist.native.linear_layout import LINEAR_BLOCKS, LINEAR_HEADER, _python_linear

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.nonlinear import NonlinearController


def _frozen(value: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{what} is not an array of numbers") from exc
    if arr.size == 0 and math.prod(shape) == 0:
        arr = arr.reshape(shape)
    elif arr.shape != shape:
        if arr.size == math.prod(shape) and arr.ndim <= 1 and len(shape) == 2 and 1 in shape:
            arr = arr.reshape(shape)
        else:
            raise DimensionError(f"{what} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise DimensionError(f"{what} has a value that is not a finite number")
    arr.setflags(write=False)
    return arr


def _shaped(value: object, shape: tuple[int, int]) -> np.ndarray:
    """*value* as a float array, reshaped to *shape* when it has that many elements."""
    arr = np.asarray(value, dtype=float)
    return arr.reshape(shape) if arr.size == shape[0] * shape[1] else arr


def _optional(value: object | None) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


def _limits(value: object | None, m: int, fill: float, what: str) -> np.ndarray:
    if value is None:
        arr = np.full(m, fill)
    else:
        arr = np.array(value, dtype=float).reshape(-1)
        if arr.shape != (m,):
            raise DimensionError(f"{what} has {arr.size} values, expected {m}")
        if np.any(np.isnan(arr)):
            raise DimensionError(f"{what} has a value that is not a number")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class LinearController:
    """A digital linear controller in one state-space form (see the module docstring).

    Sizes: ``n`` plant states, ``m`` inputs, ``ny`` measured outputs, ``nr``
    references, ``nz`` controller states. All matrices are read-only
    float64 arrays; vectors are 1-D.

    Attributes
    ----------
    Ac, By, Br, Bu, Cc, Dy, Dr:
        The form's matrices.
    Ez, Ey:
        The estimate ``x_hat = x_op + Ez z + Ey dy`` (zero-sized when
        ``has_estimate`` is False).
    x_op, u_op, y_op, r_op:
        Operating point of the plant's states and inputs, and the measured
        and tracked outputs there.
    z0:
        The controller state at the start of a run.
    state_map:
        ``(nz, n)``: the controller state that belongs to an estimate
        ``x`` of the plant's state is ``state_map @ (x - x_op)`` (to start
        the controller at a given estimate).
    rate:
        Sample rate [Hz] the controller was made for; None for a gain that
        is applied at whatever rate the run uses.
    state_names, input_names, output_names, tracked_names:
        The plant's states and inputs, the measured outputs (``y``, states
        of the plant) and the tracked outputs (``r``).
    u_min, u_max:
        Input limits the command is saturated to (the plant's actuator
        limits apply in the simulation; these are what the exported code uses).
    kind, form:
        ``"lqr"``, ``"lqg"``, ``"none"`` or a builder's name; the Kalman form
        (``"current"``, ``"predictor"``) or ``""``.
    has_estimate:
        Whether ``Ez``, ``Ey`` give a state estimate.
    design:
        The design it came from, if any (not compared, not printed).
    """

    Ac: np.ndarray
    By: np.ndarray
    Br: np.ndarray
    Bu: np.ndarray
    Cc: np.ndarray
    Dy: np.ndarray
    Dr: np.ndarray
    Ez: np.ndarray
    Ey: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    r_op: np.ndarray
    z0: np.ndarray
    state_map: np.ndarray
    rate: float | None
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    tracked_names: tuple[str, ...] = ()
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    kind: str = "linear"
    form: str = ""
    has_estimate: bool = True
    design: Design | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n, m = len(self.state_names), len(self.input_names)
        ny, nr = len(self.output_names), len(self.tracked_names)
        nz = int(np.size(self.z0))
        sizes = {"n": n, "m": m, "ny": ny, "nr": nr, "nz": nz}
        for name, dims in LINEAR_BLOCKS:
            shape = tuple(sizes[d] for d in dims)
            if name in ("Ez", "Ey") and not self.has_estimate:
                shape = (0, shape[1])
            object.__setattr__(self, name, _frozen(getattr(self, name), shape, name))
        object.__setattr__(self, "z0", _frozen(self.z0, (nz,), "z0"))
        object.__setattr__(self, "state_map", _frozen(self.state_map, (nz, n), "state_map"))
        for label in ("state_names", "input_names", "output_names", "tracked_names"):
            object.__setattr__(self, label, tuple(getattr(self, label)))
        object.__setattr__(self, "u_min", _limits(self.u_min, m, -math.inf, "u_min"))
        object.__setattr__(self, "u_max", _limits(self.u_max, m, math.inf, "u_max"))
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise DesignError(f"the controller's rate must be a positive number of Hz, got {self.rate!r}")
        missing = [o for o in (*self.output_names, *self.tracked_names) if o not in self.state_names]
        if missing:
            raise DesignError(
                f"measured or tracked output(s) {', '.join(missing)} are not states "
                f"({', '.join(self.state_names)})"
            )

    def __getstate__(self) -> dict[str, object]:
        # The design stays behind when the controller goes to another process.
        state = {**self.__dict__, "design": None}
        state.pop("_packed", None)
        return state

    # -- sizes -------------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Plant states ``n``."""
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_outputs(self) -> int:
        """Measured outputs ``ny``."""
        return len(self.output_names)

    @property
    def n_references(self) -> int:
        return len(self.tracked_names)

    @property
    def n_z(self) -> int:
        """Controller states ``nz``."""
        return int(self.z0.size)

    @property
    def outputs(self) -> tuple[str, ...]:
        """The measured states, in the order of ``y`` (what the simulator measures)."""
        return self.output_names

    @property
    def tracked(self) -> tuple[str, ...]:
        return self.tracked_names

    @property
    def output_index(self) -> tuple[int, ...]:
        return tuple(self.state_names.index(o) for o in self.output_names)

    # -- the numbers the compiled core and the C code read -------------------------------------
    def packed(self) -> np.ndarray:
        """The controller as one float vector: :data:`LINEAR_HEADER`, then :data:`LINEAR_BLOCKS`.

        This is the parameter vector of the compiled ``linear_*`` functions
        (a new array each call).
        """
        return self._packed.copy()

    @cached_property
    def _packed(self) -> np.ndarray:
        # Without an estimate the estimate has no rows (linear_estimate writes nothing).
        sizes = {"n": int(self.Ez.shape[0]), "m": self.n_inputs, "ny": self.n_outputs,
                 "nr": self.n_references, "nz": self.n_z}
        header = np.zeros(len(LINEAR_HEADER))
        for key in ("nz", "ny", "nr", "m", "n"):
            header[LINEAR_HEADER.index(key)] = sizes[key]
        parts = [header]
        offset = header.size
        for name, _dims in LINEAR_BLOCKS:
            block = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            header[LINEAR_HEADER.index(name)] = offset
            parts.append(block)
            offset += block.size
        return np.concatenate(parts)

    # -- the controller in Python (the very source the core compiles) ---------------------------
    def output(self, z: object, y: object, r: object = ()) -> np.ndarray:
        """The command ``u`` (absolute, before saturation) for state *z*, measurements *y*, references *r*."""
        u = np.zeros(self.n_inputs)
        _python_linear()["linear_output"](0.0, *self._vectors(z, y, r), self.packed(), u)
        return u

    def update(self, z: object, y: object, r: object, u_applied: object) -> np.ndarray:
        """The next controller state after *u_applied* (absolute) acted."""
        zn = np.zeros(self.n_z)
        ua = np.asarray(u_applied, dtype=float).reshape(self.n_inputs)
        _python_linear()["linear_update"](0.0, *self._vectors(z, y, r), ua, self.packed(), zn)
        return zn

    def estimate(self, z: object, y: object) -> np.ndarray | None:
        """The absolute state estimate behind the command (None without an estimate)."""
        if not self.has_estimate:
            return None
        x = np.zeros(self.n_states)
        zv, yv, rv = self._vectors(z, y, ())
        _python_linear()["linear_estimate"](0.0, zv, yv, rv, self.packed(), x)
        return x

    def _vectors(self, z: object, y: object, r: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        zv = np.asarray(z, dtype=float).reshape(self.n_z)
        yv = np.asarray(y, dtype=float).reshape(self.n_outputs)
        rv = np.asarray(r, dtype=float).reshape(-1)
        if rv.size != self.n_references:
            rv = np.resize(rv, self.n_references) if rv.size else np.array(self.r_op)
        return zv, yv, rv

    def runtime(self, state_names: Sequence[str] | None = None) -> LinearRuntime:
        """This controller as a :class:`PythonController` (for checks of the compiled core)."""
        return LinearRuntime(self)

    def start_at(self, x_estimate: object) -> LinearController:
        """The same controller started from the absolute state estimate *x_estimate*."""
        dx = np.asarray(x_estimate, dtype=float).reshape(self.n_states) - self.x_op
        return _replace(self, z0=self.state_map @ dx)

    def as_nonlinear(self) -> NonlinearController:
        """This controller as a :class:`NonlinearController` whose source calls the linear
        library on :meth:`packed`: the same sums in the same order, so it runs (in the core, in
        Python, and in the C that :mod:`equilibrist.native.nonlinear_library` writes from it) to the
        bit as this one. A linear controller of any making exports this way."""
        from equilibrist.control.nonlinear import NonlinearController

        if self.rate is None:
            raise ControllerError("the linear controller has no rate: a digital controller's "
                                  "source needs one (give rate=...)")
        roles = ("output", "update") + (("estimate",) if self.has_estimate else ())
        source = "\n\n".join(_AS_NONLINEAR[role] for role in roles) + "\n"
        return NonlinearController(
            name=self.kind, source=source, params=self.packed(), z0=self.z0, rate=self.rate,
            x_op=self.x_op, u_op=self.u_op, state_names=self.state_names,
            input_names=self.input_names, output_names=self.output_names,
            tracked_names=self.tracked_names, has_estimate=self.has_estimate,
            settings={"linear": self.describe()})

    def describe(self) -> dict[str, object]:
        """The controller as JSON-able data (recorded with every result)."""
        out: dict[str, object] = {"kind": self.kind, "rate": self.rate,
                                  "outputs": list(self.output_names),
                                  "tracked": list(self.tracked_names)}
        if self.form:
            out["form"] = self.form
        for name, _dims in LINEAR_BLOCKS[:7]:
            out[name] = np.asarray(getattr(self, name)).tolist()
        return out

    @property
    def fingerprint(self) -> str:
        """12 hex digits identifying the controller's numbers and names."""
        h = hashlib.sha256(self.packed().tobytes())
        for names in (self.state_names, self.input_names, self.output_names, self.tracked_names):
            h.update(",".join(names).encode() + b";")
        return h.hexdigest()[:12]

    # -- constructors --------------------------------------------------------------------------
    @classmethod
    def state_feedback(
        cls,
        K: object,
        *,
        x_op: object,
        u_op: object,
        state_names: Sequence[str] | None = None,
        input_names: Sequence[str] | None = None,
        Kc: object | None = None,
        tracked: Sequence[str] = (),
        rate: float | None = None,
        u_min: object | None = None,
        u_max: object | None = None,
        design: Design | None = None,
    ) -> LinearController:
        """LQR: ``u = u_op - K (x - x_op) + Kc (r - r_op)`` on the measured full state.

        No controller state (``nz = 0``): ``Dy = -K``, ``Dr = Kc``; the
        estimate is the measured state (``Ey = I``).
        """
        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m = xo.size, uo.size
        states = tuple(state_names) if state_names is not None else tuple(f"x{i}" for i in range(n))
        inputs = tuple(input_names) if input_names is not None else tuple(f"u{i}" for i in range(m))
        Km = _frozen(_shaped(K, (m, n)), (m, n), "K")
        tracked = tuple(tracked)
        if Kc is None:
            if tracked:
                raise DesignError("tracked outputs given without a reference gain Kc")
            Kcm = np.zeros((m, 0))
        else:
            if not tracked:
                raise DesignError("a reference gain Kc needs the names of the tracked outputs")
            Kcm = _frozen(_shaped(Kc, (m, len(tracked))), (m, len(tracked)), "Kc")
        r_op = xo[[states.index(t) for t in tracked if t in states]]
        return cls(
            Ac=np.zeros((0, 0)), By=np.zeros((0, n)), Br=np.zeros((0, len(tracked))),
            Bu=np.zeros((0, m)), Cc=np.zeros((m, 0)), Dy=-Km, Dr=Kcm,
            Ez=np.zeros((n, 0)), Ey=np.eye(n), x_op=xo, u_op=uo, y_op=xo, r_op=r_op,
            z0=np.zeros(0), state_map=np.zeros((0, n)), rate=rate, state_names=states,
            input_names=inputs, output_names=states, tracked_names=tracked,
            u_min=_optional(u_min), u_max=_optional(u_max), kind="lqr", design=design,
        )

    @classmethod
    def lqg(
        cls,
        K: object,
        *,
        Ad: object,
        Bd: object,
        Kf: object,
        outputs: Sequence[str],
        x_op: object,
        u_op: object,
        rate: float,
        form: str = "current",
        state_names: Sequence[str] | None = None,
        input_names: Sequence[str] | None = None,
        Kc: object | None = None,
        tracked: Sequence[str] = (),
        x_hat0: object | None = None,
        u_min: object | None = None,
        u_max: object | None = None,
        design: Design | None = None,
    ) -> LinearController:
        """Discrete LQG: Kalman filter on the measured states *outputs*, feedback on its estimate.

        The controller state is the predicted deviation ``xhat_{k|k-1}``.
        ``form="current"`` (``Kf = M``): ``xhat = z + M (dy - C z)``,
        ``u = u_op - K xhat + Kc dr``, ``z+ = Ad xhat + Bd du``.
        ``form="predictor"`` (``Kf = L``): ``u = u_op - K z + Kc dr``,
        ``z+ = Ad z + Bd du + L (dy - C z)``. The matrices come from
        :func:`equilibrist.control.lqg.lqg_compensator` (inputs ``[u; y; r]``).
        *x_hat0* is the starting estimate as a deviation (default zero).
        """
        from equilibrist.control import fixed
        from equilibrist.control.lqg import lqg_compensator
        from equilibrist.numeric.linear import LinearModel

        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m = xo.size, uo.size
        states = tuple(state_names) if state_names is not None else tuple(f"x{i}" for i in range(n))
        inputs = tuple(input_names) if input_names is not None else tuple(f"u{i}" for i in range(m))
        outs = tuple(outputs)
        bad = [o for o in outs if o not in states]
        if bad:
            raise DesignError(f"measured output(s) {', '.join(bad)} are not states ({', '.join(states)})")
        C = np.zeros((len(outs), n))
        for row, o in enumerate(outs):
            C[row, states.index(o)] = 1.0
        if form not in ("current", "predictor"):
            raise DesignError(f"Kalman filter form {form!r}: expected 'current' or 'predictor'")
        plant = LinearModel(
            A=_frozen(Ad, (n, n), "Ad"), B=_frozen(_shaped(Bd, (n, m)), (n, m), "Bd"),
            C=C, D=np.zeros((len(outs), m)), state_names=states, input_names=inputs,
            output_names=outs, x0=xo, u0=uo, dt=1.0 / float(rate),
        )
        Km = _shaped(K, (m, n))
        Kfm = _shaped(Kf, (n, len(outs)))
        tracked = tuple(tracked)
        if Kc is not None and not tracked:
            raise DesignError("a reference gain Kc needs the names of the tracked outputs")
        comp = lqg_compensator(plant, Km, Kfm, Kc, tracked=tracked, form=form)
        p, nr = len(outs), len(comp.tracked_names)
        # The estimate behind the command: the estimator's own (control.kalman.realize).
        if comp.Ez is None or comp.Ey is None:
            raise DesignError("the LQG's estimate needs a discrete compensator")
        Ez, Ey = comp.Ez, comp.Ey
        z0 = np.zeros(n) if x_hat0 is None else np.asarray(x_hat0, dtype=float).reshape(n)
        return cls(
            Ac=comp.A, Bu=comp.B[:, :m], By=comp.B[:, m : m + p], Br=comp.B[:, m + p : m + p + nr],
            Cc=comp.C, Dy=comp.D[:, m : m + p], Dr=comp.D[:, m + p : m + p + nr],
            Ez=Ez, Ey=Ey, x_op=xo, u_op=uo, y_op=fixed.matvec(C, xo), r_op=comp.r0, z0=z0,
            state_map=np.eye(n), rate=float(rate), state_names=states, input_names=inputs,
            output_names=outs, tracked_names=comp.tracked_names, u_min=_optional(u_min),
            u_max=_optional(u_max), kind="lqg", form=form, design=design,
        )

    @classmethod
    def open_loop(cls, *, x_op: object, u_op: object, state_names: Sequence[str],
                  input_names: Sequence[str], outputs: Sequence[str] = ()) -> LinearController:
        """No feedback: ``u = u_op`` (the simulator adds an open-loop signal on top)."""
        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m, ny = xo.size, uo.size, len(outputs)
        states = tuple(state_names)
        y_op = xo[[states.index(o) for o in outputs]] if ny else np.zeros(0)
        return cls(
            Ac=np.zeros((0, 0)), By=np.zeros((0, ny)), Br=np.zeros((0, 0)), Bu=np.zeros((0, m)),
            Cc=np.zeros((m, 0)), Dy=np.zeros((m, ny)), Dr=np.zeros((m, 0)),
            Ez=np.zeros((0, 0)), Ey=np.zeros((0, ny)), x_op=xo, u_op=uo, y_op=y_op,
            r_op=np.zeros(0), z0=np.zeros(0), state_map=np.zeros((0, n)), rate=None,
            state_names=states, input_names=tuple(input_names), output_names=tuple(outputs),
            kind="none", has_estimate=False,
        )

    @classmethod
    def from_design(cls, design: Design, *, kind: str = "lqg", tracking: bool = False,
                    u_min: object | None = None, u_max: object | None = None) -> LinearController:
        """The ``"lqr"`` or ``"lqg"`` controller of a discrete :class:`~equilibrist.control.design.Design`.

        Its discrete gain (``lqr`` with a continuous design applies the
        continuous gain at whatever rate the run has); for ``lqg`` the
        discrete Kalman filter in the design's form. *tracking* adds the
        reference gain (an error naming why when the design has none).
        The input limits default to the design's parameters
        (``<input>_min``, ``<input>_max``).

        A design with a delay (:attr:`Design.delay`, ``N`` periods) gives a controller whose
        state holds the commands it sent and that have not acted yet, ``b = [u_{k-N}; ...;
        u_{k-1}]`` (deviations), each sample shifted and given the command :meth:`update`
        is told (the saturated command): ``lqr`` is ``u = u_op - Kx dx - Ku b + Kc dr``
        (``nz = N m``); ``lqg`` is the Kalman filter of the extended model, its state the
        prediction of ``[x; b]`` (``nz = n + N m``), its estimate the plant's part.

        A design with a velocity filter (:attr:`Design.velocity_filter`) gives the ``lqg``
        whose Kalman filter runs on the plant extended by the rig's filter of the measured
        rates (``nz = n + `` the filtered outputs), its estimate the plant's part; its
        ``lqr`` is refused (the state feedback reads the rates as measured).
        """
        if kind not in ("lqr", "lqg"):
            raise ControllerError(f"controller kind {kind!r}: expected 'lqr' or 'lqg'")
        plant = design.plant
        params = dict(design.params)
        if u_min is None:
            u_min = [float(params.get(f"{i}_min", -math.inf)) for i in plant.input_names]
        if u_max is None:
            u_max = [float(params.get(f"{i}_max", math.inf)) for i in plant.input_names]
        kc = None
        tracked: tuple[str, ...] = ()
        if tracking:
            if design.Kc is None:
                raise ControllerError(
                    f"reference tracking needs K_c: {design.kc_note or 'the design has no reference gain'}"
                )
            kc, tracked = np.asarray(design.Kc, dtype=float), tuple(design.tracked)
        if design.extended:
            return _extended(cls, design, kind=kind, Kc=kc, tracked=tracked, u_min=u_min,
                             u_max=u_max)
        if kind == "lqr":
            return cls.state_feedback(
                design.K, x_op=plant.x0, u_op=plant.u0, state_names=plant.state_names,
                input_names=plant.input_names, Kc=kc, tracked=tracked, rate=design.rate,
                u_min=u_min, u_max=u_max, design=design,
            )
        if design.discrete is None or design.rate is None:
            raise ControllerError(
                "an LQG controller needs a design with a sample rate (its discrete Kalman "
                "filter): design(system, rate=...)"
            )
        return cls.lqg(
            design.K, Ad=design.discrete.A, Bd=design.discrete.B, Kf=design.Kf,
            outputs=plant.output_names, x_op=plant.x0, u_op=plant.u0, rate=float(design.rate),
            form=design.kalman_form, state_names=plant.state_names,
            input_names=plant.input_names, Kc=kc, tracked=tracked, u_min=u_min, u_max=u_max,
            design=design,
        )


def _extended(cls: type[LinearController], design: Design, *, kind: str, Kc: np.ndarray | None,
              tracked: tuple[str, ...], u_min: object, u_max: object) -> LinearController:
    """:meth:`LinearController.from_design` of a design whose model extends the plant (a
    delay, a velocity filter; see there)."""
    from equilibrist.control import fixed
    from equilibrist.control.lqg import lqg_compensator

    plant, model = design.plant, design.model
    if model.dt is None or design.rate is None:
        raise ControllerError("a delayed design is discrete: it has a rate")
    n, m = plant.n_states, plant.n_inputs
    nb = model.n_states - n
    K = np.asarray(design.K, dtype=float)
    states, inputs = plant.state_names, plant.input_names
    r_op = plant.x0[[states.index(t) for t in tracked]]
    Kcm = np.zeros((m, 0)) if Kc is None else Kc
    if kind == "lqr" and design.velocity_filter:
        raise ControllerError(
            f"the design's velocity filter ({design.velocity_filter:g} Hz) is its Kalman "
            "filter's model: an LQR reads the rates as measured (controller lqg, or a design "
            "without velocity_filter)")
    if kind == "lqr":
        return cls(
            Ac=model.A[n:, n:], By=np.zeros((nb, n)), Br=np.zeros((nb, len(tracked))),
            Bu=model.B[n:, :], Cc=-K[:, n:], Dy=-K[:, :n], Dr=Kcm, Ez=np.zeros((n, nb)),
            Ey=np.eye(n), x_op=plant.x0, u_op=plant.u0, y_op=plant.x0, r_op=r_op,
            z0=np.zeros(nb), state_map=np.zeros((nb, n)), rate=float(design.rate),
            state_names=states, input_names=inputs, output_names=states, tracked_names=tracked,
            u_min=_optional(u_min), u_max=_optional(u_max), kind="lqr", design=design)
    comp = lqg_compensator(model, K, design.Kf, Kc, tracked=tracked, form=design.kalman_form)
    if comp.Ez is None or comp.Ey is None:
        raise DesignError("the LQG's estimate needs a discrete compensator")
    p, nr = plant.n_outputs, len(comp.tracked_names)
    C = plant.C
    state_map = np.zeros((n + nb, n))
    state_map[:n, :n] = np.eye(n)
    return cls(
        Ac=comp.A, Bu=comp.B[:, :m], By=comp.B[:, m : m + p], Br=comp.B[:, m + p : m + p + nr],
        Cc=comp.C, Dy=comp.D[:, m : m + p], Dr=comp.D[:, m + p : m + p + nr],
        Ez=comp.Ez[:n], Ey=comp.Ey[:n], x_op=plant.x0, u_op=plant.u0,
        y_op=fixed.matvec(C, plant.x0), r_op=comp.r0, z0=np.zeros(n + nb), state_map=state_map,
        rate=float(design.rate), state_names=states, input_names=inputs,
        output_names=plant.output_names, tracked_names=comp.tracked_names,
        u_min=_optional(u_min), u_max=_optional(u_max), kind="lqg", form=design.kalman_form,
        design=design)


#: :meth:`LinearController.as_nonlinear`'s source, by role: the contract's functions, each
#: the linear library's on the controller's packed vector.
_AS_NONLINEAR = {
    "output": "def output(t, z, y, r, p, u_out):\n    linear_output(t, z, y, r, p, u_out)",
    "update": "def update(t, z, y, r, u_applied, p, z_out):\n"
              "    linear_update(t, z, y, r, u_applied, p, z_out)",
    "estimate": "def estimate(t, z, y, r, p, x_out):\n    linear_estimate(t, z, y, r, p, x_out)",
}


def _replace(ctrl: LinearController, **changes: Any) -> LinearController:
    from dataclasses import replace

    return replace(ctrl, **changes)


class LinearRuntime(PythonControllerBase):
    """A :class:`LinearController` run in Python, sample by sample (the core's reference)."""

    def __init__(self, ctrl: LinearController) -> None:
        self.c = ctrl
        self.rate = ctrl.rate
        self.outputs = ctrl.output_names
        self.reset()

    def reset(self) -> None:
        self.z = np.array(self.c.z0)
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        self.estimate = self.c.estimate(self.z, y)
        return self.c.output(self.z, y, r)

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        self.z = self.c.update(self.z, y, r, u_applied)

    # The older step interface (``step`` then ``applied``), for code written against it.
    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        """:meth:`output`, remembering *t*, *y*, *r* for :meth:`applied`."""
        self._last = (t, np.array(y, dtype=float), np.array(r, dtype=float))
        return self.output(t, y, r)

    def applied(self, u: np.ndarray) -> None:
        """:meth:`update` with the arguments of the last :meth:`step`."""
        t, y, r = self._last
        self.update(t, y, r, u)

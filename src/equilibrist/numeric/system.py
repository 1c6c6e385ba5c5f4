"""A system with its parameters bound: fast ``f``, Jacobians, equilibria, linearization.

A :class:`System` is immutable: :meth:`System.with_params` returns a new one.
Its dynamics are a pure function of ``(x, u)``; the parameters are a fixed
vector ``p`` handed to the generated functions.

Finding a system by name or by the key a file records (:func:`get_system`,
:func:`system_from_key`, ...) is in :mod:`equilibrist.numeric.lookup`.
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import (
    DimensionError,
    NoEquilibriumError,
    ParameterError,
    SingularConfigurationError,
    UnknownNameError,
    finite_number,
    nearest,
)
from equilibrist.mechanics.definition import DeriveFunction
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.numeric import cache
from equilibrist.numeric.linear import LinearModel
from equilibrist.numeric.lookup import (
    _bind,
    _check_limits_order,
    _validated,
)

if TYPE_CHECKING:  # sympy is imported only when the symbolic model is asked for
    from equilibrist.mechanics.model import SymbolicModel

# Condition number past which M(q) counts as singular.
SINGULAR_CONDITION = 1e12


@dataclass(frozen=True)
class Equilibrium:
    """An operating point ``(x, u)`` with its residual ``|f(x, u)|``."""

    x: np.ndarray
    u: np.ndarray
    residual: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]

    def state(self, name: str) -> float:
        return float(self.x[self.state_names.index(name)])

    def input(self, name: str) -> float:
        return float(self.u[self.input_names.index(name)])


def _finite_vector(values: object, n: int, what: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise DimensionError(f"{what} must be numbers, got {values!r}") from None
    if arr.size != n:
        raise DimensionError(f"{what} has {arr.size} values, expected {n}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{what} has a value that is not a finite number: {arr.tolist()}")
    return arr


@dataclass(frozen=True, eq=False)
class System:
    """One system of the catalogue with its parameter values bound."""

    spec: SystemSpec
    compiled: cache.CompiledModel
    params: Mapping[str, float]

    # -- names ----------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def key(self) -> str:
        """What names the system in results and designs (a model file's path for imports)."""
        return self.compiled.entry.key

    @property
    def digest(self) -> str | None:
        """SHA-256 of the definition (a file's bytes); ``None`` for a catalogue system.

        Saved results record it beside :attr:`key`, so that a reader handed a
        system checks that it is the one the data came from.
        """
        from equilibrist.systems import files

        return files.digest_of(self.compiled.entry)

    def __reduce__(self) -> tuple[Callable[..., System], tuple[object, ...]]:
        """A system pickles as its definition's content and its parameter values
        (:func:`~equilibrist.numeric.lookup.portable`), not as the compiled objects of this
        process: a worker or a later session rebuilds it, from its cache when it has it."""
        from equilibrist.numeric.lookup import portable, unpickle_system

        return unpickle_system, portable(self)

    def __repr__(self) -> str:  # one line; a notebook shows the equations (equilibrist.notebook)
        return (f"System({self.key}: {self.spec.title}, states={list(self.state_names)}, "
                f"inputs={list(self.input_names)})")

    @classmethod
    def from_definition(cls, spec: SystemSpec, derive: DeriveFunction, **params: object) -> System:
        """A system built from a spec and its derivation, with no registration.

        The derived model is cached by the content of the definition (the
        function's source and the spec), so a system defined in a script or
        a notebook loads as fast as a catalogue one the second time.
        """
        from equilibrist.systems import files

        return _bind(files.from_definition(spec, derive), params)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.spec.state_names

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.spec.input_names

    @property
    def output_names(self) -> tuple[str, ...]:
        """The default measured outputs (the rig's sensors)."""
        return self.spec.outputs

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def state_units(self) -> tuple[str, ...]:
        return tuple(self.spec.state_unit(s) for s in self.state_names)

    @property
    def input_units(self) -> tuple[str, ...]:
        return tuple(i.unit for i in self.spec.inputs)

    def state_index(self, name: str) -> int:
        if name not in self.state_names:
            raise UnknownNameError(
                f"{self.key} has no state {name!r}: {nearest(name, self.state_names)}"
            )
        return self.state_names.index(name)

    def input_index(self, name: str) -> int:
        if name not in self.input_names:
            if not self.input_names:
                raise UnknownNameError(f"{self.key} has no input (got {name!r})")
            raise UnknownNameError(
                f"{self.key} has no input {name!r}: {nearest(name, self.input_names)}"
            )
        return self.input_names.index(name)

    # -- parameters -------------------------------------------------------------
    @cached_property
    def p(self) -> np.ndarray:
        """Parameter vector in the order of the generated functions."""
        arr = np.array([self.params[n] for n in self.spec.parameter_names], dtype=float)
        arr.setflags(write=False)
        return arr

    @property
    def input_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """``(u_min, u_max)`` from the ``<input>_min`` / ``<input>_max`` parameters."""
        low = np.array([self.params[f"{n}_min"] for n in self.input_names], dtype=float)
        high = np.array([self.params[f"{n}_max"] for n in self.input_names], dtype=float)
        return low, high

    def with_params(self, **values: float) -> System:
        """A copy with some parameters changed (validated)."""
        merged = dict(self.params)
        merged.update(_validated(self.spec, values))
        _check_limits_order(self.spec, merged)
        return System(self.spec, self.compiled, types.MappingProxyType(merged))

    # -- models -----------------------------------------------------------------
    @property
    def functions(self) -> types.ModuleType:
        """The generated numeric module (pure Python, translated to C for the core)."""
        return self.compiled.functions

    @property
    def symbolic(self) -> SymbolicModel:
        return self.compiled.symbolic

    # -- evaluation -------------------------------------------------------------
    def _xu(self, x: object, u: object | None) -> tuple[np.ndarray, np.ndarray]:
        xv = _finite_vector(x, self.n_states, f"the state of {self.key} ({', '.join(self.state_names)})")
        if u is None:
            u = np.zeros(self.n_inputs)
        what = (
            f"the input of {self.key} ({', '.join(self.input_names)})"
            if self.n_inputs
            else f"the input of {self.key} (it has none)"
        )
        uv = _finite_vector(u, self.n_inputs, what)
        self.check_regular(xv)
        return xv, uv

    def check_regular(self, x: np.ndarray) -> None:
        """Raise :class:`SingularConfigurationError` where ``M(q)`` is singular."""
        nq = self.functions.N_Q
        if nq == 0:
            return
        mass = np.empty((nq, nq))
        self._evaluate("the mass matrix", x, lambda: self.functions.mass_matrix(x, self.p, mass), mass)
        cond = np.linalg.cond(mass)
        if not math.isfinite(cond) or cond > SINGULAR_CONDITION:
            coords = ", ".join(
                f"{c} = {x[i]:g}" for i, c in enumerate(self.spec.coordinates)
            )
            why = f": {self.spec.singularity}" if self.spec.singularity else ""
            raise SingularConfigurationError(
                f"{self.key} is singular at {coords} (mass matrix not invertible){why}"
            )

    def _evaluate(self, what: str, x: np.ndarray, call: Callable[[], object],
                  *outputs: np.ndarray) -> None:
        """Run a generated function; overflow or a result that is not finite is an error.

        Finite but huge states or parameters (``1e200``) overflow in the
        model's arithmetic: that is the caller's input, reported as such.
        """
        try:
            with np.errstate(all="ignore"):
                call()
        except (ArithmeticError, ValueError):
            ok = False
        else:
            ok = all(bool(np.all(np.isfinite(o))) for o in outputs)
        if not ok:
            values = ", ".join(f"{n} = {v:g}" for n, v in zip(self.state_names, x, strict=True))
            raise ParameterError(
                f"{what} of {self.key} is not finite at {values}: the state or the parameters "
                "are too large for double precision"
            )

    def f(self, x: object, u: object | None = None) -> np.ndarray:
        """``x_dot = f(x, u)`` (validated; the simulation core calls the raw function)."""
        xv, uv = self._xu(x, u)
        out = np.empty(self.n_states)
        self._evaluate("f(x, u)", xv, lambda: self.functions.f(xv, uv, self.p, out), out)
        return out

    def jacobians(self, x: object, u: object | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(df/dx, df/du)`` at ``(x, u)`` from the symbolic Jacobians."""
        xv, uv = self._xu(x, u)
        A = np.empty((self.n_states, self.n_states))
        B = np.empty((self.n_states, self.n_inputs))
        self._evaluate("the Jacobian", xv, lambda: self.functions.jac(xv, uv, self.p, A, B), A, B)
        return A, B

    def energy(self, x: object) -> float:
        """The model's conserved energy (total energy; the cmg robot's Jacobi integral)."""
        xv, _ = self._xu(x, None)
        return float(self.functions.energy(xv, self.p))

    def conserved(self, x: object) -> dict[str, float]:
        """Conserved quantities beyond the energy (momenta of cyclic coordinates)."""
        xv, _ = self._xu(x, None)
        names = self.functions.CONSERVED
        out = np.empty(len(names))
        self.functions.conserved(xv, self.p, out)
        return dict(zip(names, out.tolist(), strict=True))

    # -- operating points -------------------------------------------------------
    def _resolve(self, value: float | str) -> float:
        if isinstance(value, str):
            return float(self.params[value])
        return float(value)

    def equilibrium(
        self,
        *,
        state: Mapping[str, float] | None = None,
        inputs: Mapping[str, float] | None = None,
        free: tuple[str, ...] | None = None,
    ) -> Equilibrium:
        """Solve ``f(x, u) = 0`` for the components left free.

        Starts from the canonical operating point; *state* and *inputs*
        override components of it, and a component given explicitly is no
        longer free. *free* overrides the list of unknowns.
        """
        op = self.spec.operating_point
        state = dict(state or {})
        inputs = dict(inputs or {})
        for n in state:
            self.state_index(n)
        for n in inputs:
            self.input_index(n)
        if op is None and not state:
            raise NoEquilibriumError(
                f"{self.key} has no canonical operating point: give the point explicitly "
                f"(states {', '.join(self.state_names)})"
            )
        x = np.zeros(self.n_states)
        u = np.zeros(self.n_inputs)
        if op is not None:
            for n, v in op.state.items():
                x[self.state_index(n)] = self._resolve(v)
            for n, v in op.inputs.items():
                u[self.input_index(n)] = self._resolve(v)
        for n, v in state.items():
            x[self.state_index(n)] = finite_number(n, v)
        for n, v in inputs.items():
            u[self.input_index(n)] = finite_number(n, v)
        if free is None:
            base = () if op is None else op.free
            free = tuple(c for c in base if c not in state and c not in inputs)
        for c in free:
            if c not in self.state_names and c not in self.input_names:
                raise UnknownNameError(f"{self.key} has no state or input {c!r} to solve for")
        self.check_regular(x)
        if free:
            x, u = self._solve(x, u, free, fixed={**state, **inputs})
        resid = self.f(x, u)
        return Equilibrium(x, u, float(np.linalg.norm(resid)), self.state_names, self.input_names)

    def _solve(
        self, x: np.ndarray, u: np.ndarray, free: tuple[str, ...], fixed: Mapping[str, float]
    ) -> tuple[np.ndarray, np.ndarray]:
        out = np.empty(self.n_states)
        self.functions.f(x, u, self.p, out)
        if not out.any():
            # Already exactly an equilibrium (an imported model's keyframe, upright with no
            # input): where least_squares would stop at once, without importing scipy's
            # optimize (half a second of a first run).
            return x.copy(), u.copy()
        from scipy.optimize import least_squares

        sx = [self.state_names.index(c) for c in free if c in self.state_names]
        su = [self.input_names.index(c) for c in free if c in self.input_names]
        fns = self.functions

        def split(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            xx, uu = x.copy(), u.copy()
            xx[sx] = z[: len(sx)]
            uu[su] = z[len(sx) :]
            return xx, uu

        def resid(z: np.ndarray) -> np.ndarray:
            xx, uu = split(z)
            out = np.empty(self.n_states)
            fns.f(xx, uu, self.p, out)
            return out

        def jac(z: np.ndarray) -> np.ndarray:
            xx, uu = split(z)
            A = np.empty((self.n_states, self.n_states))
            B = np.empty((self.n_states, self.n_inputs))
            fns.jac(xx, uu, self.p, A, B)
            return np.hstack([A[:, sx], B[:, su]])

        def solve_from(start: np.ndarray) -> tuple[np.ndarray, float, float]:
            try:
                with np.errstate(all="ignore"):
                    z = least_squares(resid, start, jac=jac, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
                    res = float(np.linalg.norm(resid(z)))
                    scale = 1.0 + float(np.linalg.norm(np.abs(jac(z)) @ np.abs(z)))
            except (ArithmeticError, ValueError):  # a start where f is not defined
                return start, math.inf, 1.0
            if not (np.all(np.isfinite(z)) and math.isfinite(res)):
                return start, math.inf, 1.0
            return z, res, scale

        # The given point first; where f is flat there (the seesaw's thrust
        # at theta = 0 fixes cos(theta), not theta), a few spread starts,
        # fixed so that the answer does not depend on chance.
        z0 = np.concatenate([x[sx], u[su]])
        spread = np.random.default_rng(0).uniform(-1.0, 1.0, (8, z0.size))
        starts = [z0] + [z0 + step * (1.0 + np.abs(z0)) for step in spread]
        best = solve_from(z0)
        for start in starts[1:]:
            if best[1] <= 1e-8 * best[2]:
                break
            candidate = solve_from(start)
            if candidate[1] < best[1]:
                best = candidate
        z_best, res, scale = best
        xs, us = split(z_best)
        if res > 1e-8 * scale:
            given = ", ".join(f"{k} = {v:g}" for k, v in fixed.items()) or self._point_text(x, u, free)
            raise NoEquilibriumError(
                f"{self.key} has no equilibrium at {given} with {', '.join(free)} free: "
                f"the best found leaves |f| = {res:.3g}"
            )
        return xs, us

    def _point_text(self, x: np.ndarray, u: np.ndarray, free: tuple[str, ...]) -> str:
        """How a message names the operating point: its given components."""
        parts = [f"{n} = {v:g}" for n, v in zip(self.state_names, x, strict=True) if v != 0 and n not in free]
        parts += [f"{n} = {v:g}" for n, v in zip(self.input_names, u, strict=True) if v != 0 and n not in free]
        where = f"({', '.join(parts)})" if parts else "(every state zero)"
        return f"its operating point {where}"

    def operating_point(self) -> Equilibrium:
        """The canonical operating point, with its free components solved."""
        return self.equilibrium()

    def linearize(
        self,
        x0: object | None = None,
        u0: object | None = None,
        *,
        outputs: tuple[str, ...] | list[str] | None = None,
    ) -> LinearModel:
        """Numeric ``A, B, C, D`` at ``(x0, u0)`` (default: the canonical operating point).

        The residual ``|f(x0, u0)|`` says whether the point is an equilibrium.
        """
        if x0 is None and u0 is None:
            eq = self.operating_point()
            xv, uv = eq.x, eq.u
        else:
            if x0 is None or (u0 is None and self.n_inputs):
                raise DimensionError("linearize needs both x0 and u0, or neither")
            xv, uv = self._xu(x0, u0)
        A, B = self.jacobians(xv, uv)
        names = tuple(outputs) if outputs is not None else (self.output_names or self.state_names)
        base = LinearModel(
            A=A,
            B=B,
            C=np.zeros((0, self.n_states)),
            D=np.zeros((0, self.n_inputs)),
            state_names=self.state_names,
            input_names=self.input_names,
            output_names=(),
            x0=xv,
            u0=uv,
            residual=float(np.linalg.norm(self.f(xv, uv))),
            system=self.key,
            params=self.params,
            state_units=self.state_units,
            input_units=self.input_units,
        )
        return base.with_outputs(names)


__all__ = [
    "SINGULAR_CONDITION",
    "Equilibrium",
    "System",
]

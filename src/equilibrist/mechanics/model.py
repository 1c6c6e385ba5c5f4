"""Symbolic models: from sympy.physics.mechanics to ``M(q) q_ddot = F`` and ``x_dot = f(x, u)``.

Each system module writes a *derivation*: a function that receives a
:class:`Derivation` context (its coordinates as dynamicsymbols, its inputs and
parameters as symbols), builds frames, points, bodies and loads, and hands a
Lagrangian or a Kane formulation back through :meth:`Derivation.lagrange` or
:meth:`Derivation.kane`. No equation of motion is typed in.

After derivation every time function is replaced by a plain symbol named as
the state (``theta(t)`` -> ``theta``, ``theta'(t)`` -> ``theta_dot``), so the
model is an ordinary expression in states, inputs and parameters.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import sympy as sp

from equilibrist.mechanics.spec import SystemSpec

if TYPE_CHECKING:
    from sympy.physics import mechanics as me


@dataclass(frozen=True, eq=False)
class SymbolicModel:
    """The derived equations of one system, in plain symbols.

    ``M`` and ``F`` are None for first-order models that are not mechanical
    (the servo ball-and-beam); ``f`` is always there.
    """

    spec_key: str
    method: str
    states: tuple[sp.Symbol, ...]
    inputs: tuple[sp.Symbol, ...]
    params: tuple[sp.Symbol, ...]
    f: sp.Matrix
    M: sp.Matrix | None = None
    F: sp.Matrix | None = None
    energy: sp.Expr | None = None
    conserved: dict[str, sp.Expr] = field(default_factory=dict)
    extras: dict[str, sp.Expr] = field(default_factory=dict)
    # Named points of the mechanism (joint anchors, centres of mass) as
    # ``(x, y, z)`` column vectors in the Newtonian frame, and the pairs of
    # them joined by a link: what a generic drawing of the system shows.
    points: dict[str, sp.Matrix] = field(default_factory=dict)
    links: tuple[tuple[str, str], ...] = ()
    # How the generated code forms df/dx and df/du: "symbolic" (the derivative of f's
    # expressions, ``A`` and ``B`` below) or "mass" (from M and F: dq_ddot/dx =
    # M^-1 (dF/dx - dM/dx q_ddot), with q_ddot computed first; far cheaper to derive for
    # an imported tree, whose f is a large quotient).
    jacobian_form: str = "symbolic"

    @property
    def n_q(self) -> int:
        return 0 if self.M is None else self.M.shape[0]

    @cached_property
    def A(self) -> sp.Matrix:
        """Symbolic ``df/dx``."""
        return self.f.jacobian(sp.Matrix(self.states))

    @cached_property
    def B(self) -> sp.Matrix:
        """Symbolic ``df/du`` (zero columns for a system without input)."""
        if not self.inputs:
            return sp.zeros(len(self.states), 0)
        return self.f.jacobian(sp.Matrix(self.inputs))

    def q_ddot_symbols(self) -> sp.Matrix:
        names = [s.name for s in self.states[: self.n_q]]
        return sp.Matrix([sp.Symbol(f"{n}_ddot") for n in names])

    def equations(self) -> sp.Matrix:
        """``M q_ddot - F`` (zero along a motion), or ``x_dot - f``."""
        if self.M is not None and self.F is not None:
            return self.M * self.q_ddot_symbols() - self.F
        xdot = sp.Matrix([sp.Symbol(f"{s.name}__rate") for s in self.states])
        return xdot - self.f


class Derivation:
    """The context a system's derivation is written in.

    Attributes
    ----------
    t:
        Time.
    q, qd:
        Coordinates as dynamicsymbols and their first derivatives.
    u:
        Input symbols by name (plain symbols: they are specified, not solved).
    p:
        Parameter symbols by name.
    N, O:
        A Newtonian frame and its origin, for convenience.

    The time functions, the frame and the point are made on first use, so a
    derivation written in plain symbols (an imported tree's, :meth:`coordinates`)
    does not import sympy.physics (a quarter of a second, for its units).
    """

    def __init__(self, spec: SystemSpec) -> None:
        self.spec = spec
        self.u = {i.name: sp.Symbol(i.name, real=True) for i in spec.inputs}
        self.p = {p.name: sp.Symbol(p.name, real=True) for p in spec.all_parameters}

    @cached_property
    def t(self) -> sp.Symbol:
        from sympy.physics import mechanics as me

        return me.dynamicsymbols._t

    @cached_property
    def q(self) -> list[sp.Function]:
        from sympy.physics import mechanics as me

        return [me.dynamicsymbols(c) for c in self.spec.coordinates]

    @cached_property
    def qd(self) -> list[sp.Expr]:
        return [qi.diff(self.t) for qi in self.q]

    @cached_property
    def N(self) -> me.ReferenceFrame:
        from sympy.physics import mechanics as me

        return me.ReferenceFrame("N")

    @cached_property
    def O(self) -> me.Point:  # noqa: E743 (the origin's conventional name)
        from sympy.physics import mechanics as me

        origin = me.Point("O")
        origin.set_vel(self.N, 0)
        return origin

    def coordinates(self) -> tuple[list[sp.Symbol], list[sp.Symbol]]:
        """The coordinates and their rates as plain symbols (``theta``, ``theta_dot``), the
        names a model's states have: for a derivation that needs no time functions."""
        return ([sp.Symbol(c, real=True) for c in self.spec.coordinates],
                [sp.Symbol(f"{c}_dot", real=True) for c in self.spec.coordinates])

    # -- helpers shared by the systems ------------------------------------
    def coord(self, name: str) -> sp.Function:
        return self.q[self.spec.coordinates.index(name)]

    def rate(self, name: str) -> sp.Expr:
        return self.qd[self.spec.coordinates.index(name)]

    def _plain(self) -> dict[sp.Expr, sp.Symbol]:
        """Substitution of time functions by plain state symbols (rates first)."""
        subs: dict[sp.Expr, sp.Symbol] = {}
        for c, qi, qdi in zip(self.spec.coordinates, self.q, self.qd, strict=True):
            subs[qi.diff(self.t, 2)] = sp.Symbol(f"{c}_ddot", real=True)
            subs[qdi] = sp.Symbol(f"{c}_dot", real=True)
        for c, qi in zip(self.spec.coordinates, self.q, strict=True):
            subs[qi] = sp.Symbol(c, real=True)
        return subs

    def plain(self, expr: sp.Expr | sp.Matrix) -> sp.Expr | sp.Matrix:
        """*expr* with ``q(t)``, ``q'(t)``, ``q''(t)`` replaced by plain symbols."""
        from sympy.physics import mechanics as me

        return me.msubs(expr, self._plain())

    # -- finishing a derivation --------------------------------------------
    def lagrange(
        self,
        lagrangian: sp.Expr,
        *,
        loads: Sequence[tuple[object, me.Vector]] = (),
        energy: sp.Expr | None = None,
        conserved: dict[str, sp.Expr] | None = None,
        extras: dict[str, sp.Expr] | None = None,
    ) -> SymbolicModel:
        """Equations of motion by Lagrange's method.

        *loads* are ``(point or frame, vector)`` pairs: forces at points and
        torques on frames, as :class:`sympy.physics.mechanics.LagrangesMethod`
        takes them (generalized forces come from their virtual work).
        """
        from sympy.physics import mechanics as me

        lm = me.LagrangesMethod(lagrangian, self.q, forcelist=list(loads), frame=self.N)
        lm.form_lagranges_equations()
        return self._finish("Lagrange", lm.mass_matrix, lm.forcing, energy, conserved, extras)

    def kane(
        self,
        *,
        bodies: Iterable[object],
        loads: Sequence[tuple[object, me.Vector]] = (),
        energy: sp.Expr | None = None,
        conserved: dict[str, sp.Expr] | None = None,
        extras: dict[str, sp.Expr] | None = None,
        armature: dict[str, sp.Expr] | None = None,
        points: dict[str, me.Point] | None = None,
        links: Sequence[tuple[str, str]] = (),
    ) -> SymbolicModel:
        """Equations of motion by Kane's method, with the speeds ``u_i = q_i'``.

        Choosing the generalized speeds equal to the coordinate rates makes
        Kane's mass matrix the one of ``M(q) q_ddot = F``, comparable term by
        term with the Lagrange route. Velocities of points and frames must be
        set by the caller in terms of ``q'``; they are rewritten in the speeds.

        *armature* adds an inertia to the diagonal of ``M`` for the named
        coordinates (a rotor's reflected inertia, as MuJoCo's ``armature``).
        *points* (positions relative to ``O``) and *links* (pairs of point
        names) describe the mechanism for a generic drawing.
        """
        from sympy.physics import mechanics as me

        speeds = [me.dynamicsymbols(f"{c}_u") for c in self.spec.coordinates]
        kd = [qd - s for qd, s in zip(self.qd, speeds, strict=True)]
        km = me.KanesMethod(self.N, q_ind=self.q, u_ind=speeds, kd_eqs=kd)
        fr, frstar = km.kanes_equations(list(bodies), list(loads))
        del fr, frstar
        back: dict[sp.Expr, sp.Expr] = {}
        for s, qd in zip(speeds, self.qd, strict=True):
            back[s.diff(self.t)] = qd.diff(self.t)
            back[s] = qd
        mass = me.msubs(km.mass_matrix, back)
        forcing = me.msubs(km.forcing, back)
        if armature:
            mass = sp.Matrix(mass)
            for name, value in armature.items():
                k = self.spec.coordinates.index(name)
                mass[k, k] += value
        model = self._finish("Kane", mass, forcing, energy, conserved, extras)
        if points:
            model = self.with_points(model, points, links)
        return model

    def from_mass_matrix(
        self,
        method: str,
        mass: sp.Matrix,
        forcing: sp.Matrix,
        *,
        energy: sp.Expr | None = None,
        points: dict[str, sp.Matrix] | None = None,
        links: Sequence[tuple[str, str]] = (),
        jacobian_form: str = "symbolic",
    ) -> SymbolicModel:
        """The model of ``M(q) q_ddot = F`` formed by the caller in plain symbols
        (:meth:`coordinates`; an imported tree writes Lagrange's equations out), with its
        named *points* as ``(x, y, z)`` columns in the world, finished as :meth:`kane`
        finishes its own."""
        from dataclasses import replace

        model = replace(self._finish(method, mass, forcing, energy, None, None, plain=True),
                        jacobian_form=jacobian_form)
        return self._record_points(model, points or {}, links)

    def with_points(
        self, model: SymbolicModel, points: dict[str, me.Point], links: Sequence[tuple[str, str]] = ()
    ) -> SymbolicModel:
        """*model* with named *points* (positions from ``O`` in ``N``) and *links* recorded."""
        recorded: dict[str, sp.Matrix] = {}
        for name, point in points.items():
            r = point.pos_from(self.O)
            recorded[name] = sp.Matrix(self.plain(sp.Matrix([r.dot(self.N.x), r.dot(self.N.y), r.dot(self.N.z)])))
        return self._record_points(model, recorded, links)

    @staticmethod
    def _record_points(model: SymbolicModel, recorded: dict[str, sp.Matrix],
                       links: Sequence[tuple[str, str]]) -> SymbolicModel:
        from dataclasses import replace

        for a, b in links:
            if a not in recorded or b not in recorded:
                raise ValueError(f"link ({a}, {b}) joins a point that is not recorded")
        return replace(model, points=recorded, links=tuple((a, b) for a, b in links))

    def first_order(
        self,
        f: sp.Matrix,
        *,
        method: str,
        energy: sp.Expr | None = None,
        extras: dict[str, sp.Expr] | None = None,
    ) -> SymbolicModel:
        """A first-order model ``x_dot = f(x, u)`` over ``spec.state_names``.

        For reduced models obtained by eliminating a coordinate from a
        derived one (the servo ball-and-beam); *f* must already be in plain
        symbols.
        """
        states = tuple(sp.Symbol(n, real=True) for n in self.spec.state_names)
        return SymbolicModel(
            spec_key=self.spec.key,
            method=method,
            states=states,
            inputs=tuple(self.u.values()),
            params=tuple(self.p.values()),
            f=sp.Matrix(f),
            energy=energy,
            extras=dict(extras or {}),
        )

    def _finish(
        self,
        method: str,
        mass: sp.Matrix,
        forcing: sp.Matrix,
        energy: sp.Expr | None,
        conserved: dict[str, sp.Expr] | None,
        extras: dict[str, sp.Expr] | None,
        *,
        plain: bool = False,
    ) -> SymbolicModel:
        """The model of ``M q_ddot = F``; *plain*: the expressions are in plain symbols already."""
        if not plain:
            mass, forcing = self.plain(mass), self.plain(forcing)
            energy = None if energy is None else self.plain(energy)
            conserved = {k: self.plain(v) for k, v in (conserved or {}).items()}
            extras = {k: self.plain(v) for k, v in (extras or {}).items()}
        M = sp.Matrix(mass).applyfunc(sp.expand_trig).applyfunc(sp.factor_terms)
        F = sp.Matrix(forcing).applyfunc(sp.expand).applyfunc(sp.collect_const)
        qdd = _solve_linear(M, F)
        q_rates = sp.Matrix([sp.Symbol(f"{c}_dot", real=True) for c in self.spec.coordinates])
        f = sp.Matrix.vstack(q_rates, qdd)
        states = tuple(sp.Symbol(n, real=True) for n in self.spec.state_names)
        return SymbolicModel(
            spec_key=self.spec.key,
            method=method,
            states=states,
            inputs=tuple(self.u.values()),
            params=tuple(self.p.values()),
            f=f,
            M=M,
            F=F,
            energy=None if energy is None else sp.sympify(energy),
            conserved={k: sp.sympify(v) for k, v in (conserved or {}).items()},
            extras={k: sp.sympify(v) for k, v in (extras or {}).items()},
        )


def _solve_linear(M: sp.Matrix, F: sp.Matrix) -> sp.Matrix:
    """``M^-1 F`` symbolically; diagonal and small systems stay compact."""
    n = M.shape[0]
    if M.is_diagonal():
        return sp.Matrix([F[i] / M[i, i] for i in range(n)])
    if n <= 3:
        det = sp.factor_terms(M.det(method="berkowitz"))
        adj = M.adjugate(method="berkowitz")
        return (adj * F) / det
    return M.LUsolve(F)


def kinetic_energy(frame: me.ReferenceFrame, *bodies: me.RigidBody | me.Particle) -> sp.Expr:
    """Total kinetic energy of *bodies* in *frame*."""
    return sum((b.kinetic_energy(frame) for b in bodies), sp.Integer(0))

"""Coulomb friction in a derived model: one smooth law, written once.

Dry (Coulomb) friction resists motion with a force of constant size ``cf``
whatever the speed: ``cf * sign(v)``. The sign is not differentiable at rest
and makes the equations stiff, so a derived model uses a smooth form of it,
chosen by name:

``"atan"`` (the default)
    ``cf * atan(100 * v)``, the form of the RealAIGym double-pendulum
    benchmark's plant (its ``coulomb_fric * arctan(100 * vel)``). Note that it
    tends to ``cf * pi / 2`` at speed, not to ``cf``: a coefficient identified
    with that plant keeps its meaning here.
``"tanh"``
    ``cf * tanh(100 * v)``, which tends to ``cf`` at speed.

``sharpness`` (100 by default, in seconds per unit of ``v``) is the slope of
the smooth sign at rest: the friction acts like a viscous damping of
``cf * sharpness`` for ``|v|`` well below ``1 / sharpness``. It is in the
linearization at rest, so a design around an equilibrium sees it.

The law is used where a definition declares it (a model file's joint
friction, a catalogue rig's identified friction); the coefficient is a
parameter declared with :func:`equilibrist.mechanics.spec.friction` (it only
takes energy out, and the contract tests check energy conservation with it at
zero). The friction force returned here is the law itself, positive along
``v``: a derivation subtracts it from the joint's generalized force.

Examples
--------
>>> import sympy as sp
>>> v, cf = sp.symbols("v cf", real=True)
>>> coulomb_friction(v, cf)
cf*atan(100*v)
>>> coulomb_friction(v, cf, form="tanh")
cf*tanh(100*v)
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.errors import DefinitionError

if TYPE_CHECKING:
    import sympy as sp

#: The smooth forms of ``sign(v)`` by name; the first is the default.
FORMS = ("atan", "tanh")

#: The default slope of the smooth sign at rest [s per unit of velocity].
SHARPNESS = 100


def coulomb_friction(
    velocity: sp.Expr,
    coefficient: sp.Expr | float,
    form: str = "atan",
    *,
    sharpness: sp.Expr | float = SHARPNESS,
) -> sp.Expr:
    """The Coulomb friction force (or torque) at *velocity*, smooth, positive along it.

    Parameters
    ----------
    velocity : sympy.Expr
        The joint's rate (a plain symbol or a dynamicsymbol's derivative).
    coefficient : sympy.Expr or float
        The friction's size ``cf`` (a parameter symbol, >= 0) [N or N*m].
    form : str
        The smooth sign by name: ``"atan"`` (``cf * atan(k v)``, the default)
        or ``"tanh"`` (``cf * tanh(k v)``); see the module's text.
    sharpness : sympy.Expr or float
        ``k``, the slope of the smooth sign at rest (100 by default).

    Returns
    -------
    sympy.Expr
        ``cf * s(k * v)``: subtract it from the joint's generalized force.

    Raises
    ------
    DefinitionError
        *form* is not one of :data:`FORMS`.
    """
    import sympy as sp

    argument = sp.sympify(sharpness) * velocity
    if form == "atan":
        smooth_sign = sp.atan(argument)
    elif form == "tanh":
        smooth_sign = sp.tanh(argument)
    else:
        raise DefinitionError(
            f"Coulomb friction form {form!r} is not known: expected one of {', '.join(FORMS)}"
        )
    law: sp.Expr = sp.sympify(coefficient) * smooth_sign
    return law


__all__ = ["FORMS", "SHARPNESS", "coulomb_friction"]

"""The checks :func:`equilibrist.sim.setup.build` makes of single settings (a positive
number, the initial state, the reference, the system), and what it remembers of a
system between runs (its operating point, the initial states found regular)."""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping, Sequence

import numpy as np

from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.errors import NoEquilibriumError, SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim.controllers import LQG, StateFeedback


def positive(value: object, what: str, problems: list[str]) -> float | None:
    """*value* as a positive finite number, else None with a problem naming *what*."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        problems.append(f"{what} {value!r} is not a number")
        return None
    if not math.isfinite(v) or v <= 0:
        problems.append(f"{what} must be a positive number, got {value!r}")
        return None
    return v


def _initial_state(system: System, x0: object, x_op: np.ndarray, problems: list[str]) -> np.ndarray:
    x = x_op.copy()
    if x0 is None:
        return x
    if isinstance(x0, Mapping):
        for name, value in x0.items():
            if name not in system.state_names:
                from equilibrist.errors import nearest

                problems.append(f"initial state: no state {name!r} ({nearest(str(name), system.state_names)})")
                continue
            try:
                v = float(value)
            except (TypeError, ValueError):
                problems.append(f"initial state {name} = {value!r} is not a number")
                continue
            if not math.isfinite(v):
                problems.append(f"initial state {name} = {value} is not a finite number")
                continue
            x[system.state_names.index(name)] = v
        return x
    try:
        arr = np.asarray(x0, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        problems.append(f"initial state {x0!r} is not a vector of numbers")
        return x
    if arr.size != system.n_states:
        problems.append(
            f"initial state has {arr.size} values, expected {system.n_states} "
            f"({', '.join(system.state_names)})"
        )
        return x
    if not np.all(np.isfinite(arr)):
        problems.append(f"initial state {arr.tolist()} has a value that is not a finite number")
        return x
    return arr


# How far a reference may go from the operating point, in units of the
# tracked state's region (its width; 1 in the state's unit where unbounded).
REFERENCE_REACH = 1e12


def _check_reference(ref: np.ndarray, times: np.ndarray, tracked: Sequence[str],
                     r_op: np.ndarray, region_spec: Mapping[str, tuple[float, float]]) -> None:
    """Refuse a reference that is not finite, or so far away its command would overflow.

    A reference may lie outside the system's region (the run then falls,
    as it would on the rig), but not beyond :data:`REFERENCE_REACH` times
    that region's width from the operating point: the command ``K_c r``
    of such a value is no longer a number the plant can take.
    """
    for j, name in enumerate(tracked):
        col = ref[:, j]
        lo, hi = region_spec.get(name, (-math.inf, math.inf))
        width = float(hi) - float(lo)
        scale = width if math.isfinite(width) and width > 0 else 1.0
        reach = REFERENCE_REACH * scale
        bad = ~np.isfinite(col) | (np.abs(col - r_op[j]) > reach)
        if bad.any():
            k = int(np.nonzero(bad)[0][0])
            raise SimulationError(
                f"the reference of {name} is {col[k]:g} at t = {times[k]:g} s: a reference must "
                f"stay finite and within {reach:g} of the operating point {r_op[j]:g} "
                f"({REFERENCE_REACH:g} times the width of {name}'s region)"
            )


def check_system(system: object) -> None:
    """Refuse anything but a :class:`~equilibrist.numeric.system.System` as the plant."""
    if not isinstance(system, System):
        raise SimulationError(
            f"system = {system!r}: expected a System (equilibrist.get_system(name)), "
            f"not {type(system).__name__}"
        )


def _names(value: object) -> bool:
    """Whether *value* is a list (or tuple) of names."""
    return (isinstance(value, Sequence) and not isinstance(value, str | bytes)
            and all(isinstance(v, str) for v in value))


# What is known of a system (it is immutable): whether it has a canonical
# operating point, and initial states checked regular. Solving the point
# and the mass matrix's condition number cost more than a short run.
_KNOWN: weakref.WeakKeyDictionary[System, dict[str | bytes, bool]] = weakref.WeakKeyDictionary()
_KNOWN_MAX = 256


def _known(system: System) -> dict[str | bytes, bool]:
    known = _KNOWN.get(system)
    if known is None or len(known) > _KNOWN_MAX:
        known = _KNOWN[system] = {}
    return known


def _has_operating_point(system: System) -> bool:
    known = _known(system)
    found = known.get("operating point")
    if found is None:
        try:
            system.operating_point()
            found = True
        except NoEquilibriumError:
            found = False
        known["operating point"] = found
    return found


def _check_regular(system: System, x: np.ndarray) -> None:
    """``system.check_regular(x)``, remembered for the states it passed."""
    known = _known(system)
    key = x.tobytes()
    if key not in known:
        system.check_regular(x)
        known[key] = True


def operating_point(system: System, controller: object) -> tuple[np.ndarray, np.ndarray]:
    """The controller's operating point; the system's canonical one for others.

    A system without a canonical point (the zxz gyroscope) runs open loop
    about zero input, with deviations measured from zero.
    """
    if isinstance(controller, NonlinearController) or (
        isinstance(controller, StateFeedback | LQG | LinearController) and controller.kind != "none"
    ):
        return np.array(controller.x_op), np.array(controller.u_op)
    try:
        eq = system.operating_point()
    except NoEquilibriumError:
        return np.zeros(system.n_states), np.zeros(system.n_inputs)
    return np.array(eq.x), np.array(eq.u)

"""Conversion to and from python-control's ``StateSpace``.

:func:`to_statespace` carries the names of states, inputs and outputs and
the sample period (python-control writes continuous time as ``dt = 0``),
so that ``control.interconnect`` can wire a plant and a compensator by
name. :func:`from_statespace` goes back to a :class:`LinearModel`; the
operating point is not part of a ``StateSpace``, so it is given (default
zero).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import _checks
from equilibrist.control.lqg import Compensator
from equilibrist.errors import DesignError
from equilibrist.numeric.linear import LinearModel

if TYPE_CHECKING:
    import control


def to_statespace(
    model: LinearModel | Compensator, *, name: str | None = None
) -> control.StateSpace:
    """A named ``control.StateSpace`` of a linear model or compensator.

    Parameters
    ----------
    model:
        A :class:`LinearModel` (continuous or discrete) or a
        :class:`~equilibrist.control.lqg.Compensator`.
    name:
        The system's name in python-control (default: the model's system
        key, or ``"compensator"``).
    """
    import control

    if not isinstance(model, (LinearModel, Compensator)):
        raise DesignError(
            f"to_statespace needs a LinearModel or a Compensator, got {type(model).__name__}"
        )
    if name is None:
        name = (model.system or "plant") if isinstance(model, LinearModel) else "compensator"
    return control.ss(
        model.A,
        model.B,
        model.C,
        model.D,
        0 if model.dt is None else model.dt,
        states=list(model.state_names),
        inputs=list(model.input_names),
        outputs=list(model.output_names),
        name=name,
    )


def from_statespace(
    ss: control.StateSpace,
    *,
    x0: Sequence[float] | None = None,
    u0: Sequence[float] | None = None,
    system: str = "",
) -> LinearModel:
    """A :class:`LinearModel` from a ``control.StateSpace``.

    Parameters
    ----------
    ss:
        A python-control state-space system; its signal labels become the
        names. ``dt = 0`` is continuous; ``dt = True`` (discrete with an
        unspecified period) is refused.
    x0, u0:
        The operating point the model is a linearization about (default zero).
    system:
        The system key to record.
    """
    import control

    if not isinstance(ss, control.StateSpace):
        raise DesignError(f"from_statespace needs a control.StateSpace, got {type(ss).__name__}")
    dt = ss.dt
    if dt is True:
        raise DesignError(
            "the StateSpace is discrete with an unspecified period (dt=True): give dt"
        )
    A = np.asarray(ss.A, dtype=float)
    n, m = A.shape[0], np.asarray(ss.B).shape[1]
    return LinearModel(
        A=A,
        B=np.asarray(ss.B, dtype=float),
        C=np.asarray(ss.C, dtype=float),
        D=np.asarray(ss.D, dtype=float),
        state_names=tuple(ss.state_labels),
        input_names=tuple(ss.input_labels),
        output_names=tuple(ss.output_labels),
        x0=np.zeros(n) if x0 is None else _checks.matrix([x0], "x0", (1, n))[0],
        u0=np.zeros(m) if u0 is None else _checks.matrix([u0], "u0", (1, m))[0],
        system=system,
        dt=None if not dt else float(dt),
    )

"""The errors equilibrist raises on purpose.

Everything a user can get wrong raises a subclass of :class:`EquilibristError`
with a message that names what was wrong and what was expected. The command
line turns these into one line on stderr and exit status 2.
"""

from __future__ import annotations


class EquilibristError(Exception):
    """Base of every deliberate equilibrist error."""


class UnknownNameError(EquilibristError, KeyError, ValueError):
    """An unknown system, parameter, state, input or output name."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class DefinitionError(EquilibristError, ValueError):
    """A system definition (a user's file, a model file, a spec) that cannot be used."""


class CodeInDataError(DefinitionError):
    """A data file (a result, a study) names a Python system file: data never chooses code.

    A Python system file runs when it is loaded, as any import does; only the
    user decides that, by naming it (on the command line or to
    :func:`equilibrist.get_system`), never a file's own word.
    """


class ParameterError(EquilibristError, ValueError):
    """A parameter value that is out of range, not finite or malformed."""


class DimensionError(EquilibristError, ValueError):
    """Arrays or lists of the wrong size."""


class SingularConfigurationError(EquilibristError, ValueError):
    """A configuration where the model is singular (e.g. gimbal lock)."""


class NoEquilibriumError(EquilibristError, ValueError):
    """f(x, u) = 0 has no solution for the components left free."""


class DesignError(EquilibristError, ValueError):
    """A controller or estimator that cannot be designed as asked."""


class SimulationError(EquilibristError, ValueError):
    """A simulation that cannot be run as asked."""


class ControllerError(EquilibristError, ValueError):
    """A controller that does not exist, does not apply, or is not well formed."""


class ExportError(EquilibristError, ValueError):
    """An export that cannot be written as asked."""


def nearest(name: str, choices: list[str] | tuple[str, ...]) -> str:
    """A hint naming the closest of *choices* to *name* (or all of them)."""
    import difflib

    close = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.5)
    if close:
        return f"did you mean {close[0]!r}?"
    return "expected one of: " + ", ".join(choices)


def finite_number(name: str, value: object) -> float:
    """*value* as a float, or a :class:`ParameterError` naming *name*."""
    import math

    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {value!r} is not a number") from None
    if not math.isfinite(v):
        raise ParameterError(f"{name} = {v} is not a finite number")
    return v

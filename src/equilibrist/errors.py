"""The errors equilibrist raises on purpose.

Everything a user can get wrong raises a subclass of :class:`EquilibristError`
with a message that names what was wrong and what was expected. The command
line turns these into one line on stderr and exit status 2.
"""

from __future__ import annotations

import contextlib
import io
import sys
from collections.abc import Iterator


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


class UsageError(EquilibristError, ValueError):
    """A malformed value given on the command line or to a server's options."""


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


def quote_outside(text: object, *, limit: int | None = 200) -> str:
    """*text* that comes from outside (a device, a file, a plug-in) as it may be printed.

    Every control character (C0, DEL, C1), format character (the bidi overrides,
    zero-width marks) and line or paragraph separator is shown as a visible
    escape (``\\x1b``, ``\\n``, ``\\u202e``), so that no outside text can move
    the cursor, retitle or clear a terminal, or reorder the line it is shown in;
    the rest (backslashes included) is left as it is, so quoting twice changes
    nothing. The result is at most *limit* characters and ``...`` (None: no
    limit). *text* that is not a string is shown by ``str`` (an exception: its
    message).
    """
    if not isinstance(text, str):
        try:
            text = str(text)
        except Exception:  # an outside object's own __str__ may fail
            return f"(a {type(text).__name__} that cannot be shown)"
    if limit is not None:
        text = text[: limit + 1]  # every character shows as one or more
    out: list[str] = []
    size = 0
    for ch in text:
        piece = _visible(ch)
        if limit is not None and size + len(piece) > limit:
            out.append("...")
            break
        out.append(piece)
        size += len(piece)
    return "".join(out)


def quote_exception(exc: BaseException, *, limit: int | None = 200) -> str:
    """``Type: message`` of an outside exception (a plug-in's), quoted by :func:`quote_outside`."""
    return f"{quote_outside(type(exc).__name__, limit=60)}: {quote_outside(exc, limit=limit)}"


_NAMED = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}


def _visible(ch: str) -> str:
    if ch.isprintable() or ch == " ":
        return ch
    import unicodedata

    if unicodedata.category(ch) not in ("Cc", "Cf", "Cs", "Zl", "Zp"):
        return ch  # a space of another width, an unassigned or private character: harmless
    if ch in _NAMED:
        return _NAMED[ch]
    code = ord(ch)
    return f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


@contextlib.contextmanager
def outside_prints() -> Iterator[None]:
    """What a plug-in prints while it loads: kept off stdout (which may be a command's JSON)
    and written to stderr line by line through :func:`quote_outside`, so that it can neither
    corrupt an output nor move or retitle the user's terminal."""
    caught = io.StringIO()
    try:
        with contextlib.redirect_stdout(caught):
            yield
    finally:
        for line in caught.getvalue().splitlines():
            print(quote_outside(line, limit=500), file=sys.stderr)

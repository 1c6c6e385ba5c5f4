"""Entry point of the ``equilibrist`` command.

Each module of this package that defines ``add_parser(subparsers)`` adds one
subcommand; the parser it adds sets ``func`` to a function taking the parsed
arguments and returning the exit status. User mistakes (any
:class:`~equilibrist.errors.EquilibristError`, and argument errors) end with
one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import re
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Sequence
from typing import Any

from equilibrist import __version__
from equilibrist.errors import EquilibristError, quote_outside

# Order of the subcommands in --help; modules not listed come after.
_ORDER = ("systems", "show", "dynamics", "linearize", "linkage", "design", "simulate", "batch", "sweep", "identify",
          "roa", "robustness", "plot", "animate", "export", "pil", "demo")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (argparse prints the usage block otherwise).

    A value that starts with a minus sign and a digit is a value, not an
    option: argparse's own rule accepts ``-1`` but not the list
    ``-0.1,0,0,0`` that ``--state`` or ``--q`` take. So are ``-inf`` and
    ``-nan``, so that their message says what is wrong with them.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\.?\d|inf|nan)", re.IGNORECASE)

    def error(self, message: str) -> None:  # type: ignore[override]
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


class _UsageError(Exception):
    pass


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every command's, or with *command* only that one's when a
    module of that name defines it (a command imports only what it needs; its own
    ``--help`` and errors are the same). Otherwise, and for the top-level help, all."""
    if command is not None and re.fullmatch(r"[a-z][a-z_]*", command) \
            and command not in ("main", "common"):
        one = _parser_with(command)
        if one is not None:
            return one
    every = _parser_with(None)
    assert every is not None
    return every


def _parser_with(only: str | None) -> argparse.ArgumentParser | None:
    parser = _Parser(
        prog="equilibrist",
        description="Underactuated balancing systems: derive, linearize, control, simulate, "
        "show and export.",
    )
    parser.add_argument("--version", action="version", version=f"equilibrist {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    import equilibrist.cli as pkg

    names = [m.name for m in pkgutil.iter_modules(pkg.__path__)]
    if only is not None:
        if only not in names:
            return None
        module = importlib.import_module(f"{pkg.__name__}.{only}")
        if not hasattr(module, "add_parser"):
            return None
        module.add_parser(sub)
        return parser if only in sub.choices else None
    ordered = [n for n in _ORDER if n in names] + sorted(n for n in names if n not in _ORDER)
    for name in ordered:
        if name in ("main", "common"):
            continue
        module = importlib.import_module(f"{pkg.__name__}.{name}")
        if hasattr(module, "add_parser"):
            module.add_parser(sub)
    return parser


# The signal that interrupted the command (None: none did). Ctrl-C ends it with
# 130 (128 + SIGINT), SIGTERM with 143 (128 + SIGTERM), as a shell expects.
_received: int | None = None


def _terminated(signum: int, _frame: object) -> None:
    # Unwind like Ctrl-C, so that staging folders and temporary files are removed; and
    # record it, so that an exception swallowed by a finalizer still stops the work.
    global _received
    from equilibrist import interrupt

    if _received is None:
        _received = signum
    interrupt.request()
    raise KeyboardInterrupt


def interrupted_status() -> int:
    """The exit status of an interrupted command: 143 after SIGTERM, 130 after Ctrl-C."""
    return 128 + signal.SIGTERM if _received == signal.SIGTERM else 130


def _quiet_interrupts(
    previous: Callable[[sys.UnraisableHookArgs], object],
) -> Callable[[sys.UnraisableHookArgs], object]:
    """*previous* (a ``sys.unraisablehook``), except for a recorded interrupt that
    landed in a finalizer: Python would print it as "Exception ignored" with a
    traceback; recorded, it stops the work at its next check instead."""

    def hook(unraisable: sys.UnraisableHookArgs) -> object:
        from equilibrist import interrupt

        if issubclass(unraisable.exc_type, KeyboardInterrupt) and interrupt.requested():
            return None
        return previous(unraisable)

    hook.quiet_interrupts = True  # type: ignore[attr-defined]
    return hook


def main(argv: Sequence[str] | None = None) -> int:
    global _received
    _received = None
    if argv is None and threading.current_thread() is threading.main_thread():
        # The command itself (not a caller's process): a kill or Ctrl-C ends it cleanly.
        from equilibrist import interrupt

        interrupt.clear()
        signal.signal(signal.SIGTERM, _terminated)
        signal.signal(signal.SIGINT, _terminated)
        if not getattr(sys.unraisablehook, "quiet_interrupts", False):
            sys.unraisablehook = _quiet_interrupts(sys.unraisablehook)
    try:
        # Inside the try: a signal during the imports of the subcommands is an interrupt too.
        words = list(sys.argv[1:] if argv is None else argv)
        parser = build_parser(words[0] if words and not words[0].startswith("-") else None)
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        from equilibrist.cli.common import take_strays

        take_strays(args)
        # Numerical warnings of numpy and scipy are not messages for a user of
        # the command line: what goes wrong is reported as an error.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            code = int(args.func(args) or 0)
        # A command that caught the interrupt itself (to say what it kept) returns 130.
        if code == 130:
            _end_interrupted(argv)
            return interrupted_status()
        return code
    except (EquilibristError, _UsageError) as exc:
        message = _one_line(str(exc))
        prefix = "" if message.startswith("equilibrist") else "equilibrist: error: "
        print(f"{prefix}{message}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0
    except OSError as exc:
        # A file the user named that cannot be read or written.
        where = f" {exc.filename}" if exc.filename else ""
        print(_one_line(f"equilibrist: error: cannot use{where}: {exc.strerror or exc}"),
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("equilibrist: interrupted", file=sys.stderr)
        _end_interrupted(argv)
        return interrupted_status()


def _one_line(message: str) -> str:
    """*message* as the one line printed for it: its own line breaks as spaces, any other
    control character (outside text that reached it unquoted) as a visible escape."""
    return quote_outside(message.replace("\r\n", " ").replace("\n", " "), limit=None)


def _end_interrupted(argv: Sequence[str] | None) -> None:
    """End the command's own process after an interrupt, once it has unwound (its files
    written or removed) and said so: the interpreter's finalization, with the core's helper
    thread still running, could otherwise end it by the signal (-2) after that line.
    A caller's process (``main(argv)``) is left alone."""
    if argv is None and threading.current_thread() is threading.main_thread():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(interrupted_status())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

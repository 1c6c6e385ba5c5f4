"""The local playground: a live web page to watch a system balance, push it and tune it.

``equilibrist play`` serves it (:mod:`equilibrist.cli.play`). The server
(:mod:`equilibrist.web.app`, Starlette over uvicorn) runs one
:class:`~equilibrist.web.session.Session` per browser tab: the system's
compiled core in real time at the control rate, the controller redesigned
live as the page tunes it. The page (``static/``) is plain JavaScript on a
canvas, with the vendored uPlot for the strip charts; it needs no network
beyond the server. The message protocol is in ``docs/playground.md`` and
:mod:`equilibrist.web.protocol`.

Importing this package does no work; the server's libraries are imported
when an app is made, with an error naming the extra to install when missing.
"""

from __future__ import annotations

import importlib.util

from equilibrist.errors import EquilibristError


class MissingExtraError(EquilibristError, ImportError):
    """A library of an optional extra is not installed."""


def require() -> None:
    """Raise :class:`MissingExtraError` unless the web extra's libraries are installed."""
    missing = [m for m in ("starlette", "uvicorn", "websockets") if importlib.util.find_spec(m) is None]
    if missing:
        raise MissingExtraError(
            f"the playground needs {', '.join(missing)}: pip install 'equilibrist[web]'"
        )


__all__ = ["MissingExtraError", "require"]

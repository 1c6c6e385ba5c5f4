"""The local playground: a live web page to watch a system balance, push it and tune it.

``equilibrist play`` and :func:`play` serve it (:mod:`equilibrist.web.server`): one
:class:`~equilibrist.web.session.Session` per browser tab, the system's compiled core in
real time, the controller redesigned live as the page tunes it; the page (``static/``) is
plain JavaScript with the vendored uPlot, needing no network beyond the server. The
protocol: ``docs/playground.md``. Importing this package does no work; the server's
libraries are imported when an app is made, with an error naming the extra when missing.
"""

from __future__ import annotations

import importlib.util
from typing import TYPE_CHECKING

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


class MissingExtraError(EquilibristError, ImportError):
    """A library of an optional extra is not installed."""


def require() -> None:
    """Raise :class:`MissingExtraError` unless the web extra's libraries are installed."""
    missing = [m for m in ("starlette", "uvicorn", "websockets") if importlib.util.find_spec(m) is None]
    if missing:
        raise MissingExtraError(
            f"the playground needs {', '.join(missing)}: pip install 'equilibrist[web]'"
        )


def play(*systems: System, first: str | None = None, host: str = "127.0.0.1", port: int = 8050,
         browser: bool = True) -> None:
    """Serve the playground for *systems* until Ctrl-C, as ``equilibrist play`` does.

    The systems are values: a script's own (``System.from_definition``, which a
    command in another process could not rebuild), a file's or the
    catalogue's, each with its parameter values; none given offers the
    catalogue. ``port=0`` takes any free port (the address is printed).
    """
    require()
    from equilibrist.web.server import serve
    from equilibrist.web.session_design import Catalogue

    catalogue = Catalogue.of(systems) if systems else Catalogue.default()
    serve(catalogue, first=first, host=host, port=port, browser=browser)


__all__ = ["MissingExtraError", "play", "require"]

"""``equilibrist play``: the live playground in the browser.

Serves the page of :mod:`equilibrist.web` on a local port, prints its
address, opens it in the default browser where one exists, and runs until
Ctrl-C (the sessions' sockets are closed, the port freed, and the command
ends as every command does when interrupted: ``equilibrist: interrupted``,
exit status 130). It binds the
loopback interface by default: the playground has no login, so binding
another address (``--host 0.0.0.0``) lets anyone on that network drive it,
and the command says so.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from equilibrist.errors import UsageError

if TYPE_CHECKING:
    pass


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "play",
        help="a live web page to watch a system balance, push it and tune it",
        description="Start the playground: a local web page where a system balances in real "
        "time under its digital controller; push it, tune the weights, the rate, the noise "
        "and the parameters, watch the poles, download the controller as C code. Runs "
        "until Ctrl-C.",
    )
    p.add_argument("system", nargs="?", metavar="SYSTEM",
                   help="the system the page starts with (default: cartpole); a catalogue "
                        "name or the path of your own model file")
    p.add_argument("--port", default="8050", metavar="PORT",
                   help="TCP port (default 8050; 0 picks a free one)")
    p.add_argument("--host", default="127.0.0.1", metavar="ADDRESS",
                   help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser")
    p.set_defaults(func=run)


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise UsageError(f"--port {text!r} is not a port number: expected 0 to 65535") from None
    if not 0 <= port <= 65535:
        raise UsageError(f"--port {port} is out of range: expected 0 to 65535")
    return port


def run(args: argparse.Namespace) -> int:
    from equilibrist.web import require

    require()
    from equilibrist.web.server import serve
    from equilibrist.web.session_design import Catalogue

    port = _port(args.port)
    extra = () if args.system is None else (args.system,)
    serve(Catalogue.default(extra), first=args.system, host=args.host, port=port,
          browser=not args.no_browser)
    return 0

"""The playground's server: the listening socket (one clear error when a port cannot be
had), the page's application served by uvicorn until Ctrl-C, and the browser opened where
a display exists. ``equilibrist play`` and :func:`equilibrist.web.play` both serve through it.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import socket
import sys
import threading
from typing import TYPE_CHECKING

from equilibrist.errors import UsageError

if TYPE_CHECKING:
    from equilibrist.web.session_design import Catalogue


def is_loopback(host: str) -> bool:
    """Whether *host* names only this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on *host*:*port* (one clear error when it cannot be had)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise UsageError(f"--host {host!r} is not an address of this machine: {exc.strerror}") from None
    family, _, _, _, address = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            why = "is in use (another playground?): pick another with --port"
        elif exc.errno == errno.EACCES and 0 < port < 1024:
            why = ("is privileged and this user may not bind it: pick one from 1024 to 65535 "
                   "with --port (or 0 for any free one)")
        elif exc.errno == errno.EADDRNOTAVAIL:
            raise UsageError(f"--host {host!r} is not an address of this machine: "
                                    f"{exc.strerror}") from None
        else:
            why = f"cannot be bound: {exc.strerror or exc}"
        raise UsageError(f"port {port} on {host} {why}") from None
    try:
        sock.listen(128)
    except OSError as exc:
        sock.close()
        raise UsageError(f"port {port} on {host} cannot be listened on: "
                                f"{exc.strerror or exc}") from None
    sock.set_inheritable(True)
    return sock


def serve(catalogue: Catalogue, *, first: str | None = None, host: str = "127.0.0.1",
          port: int = 8050, browser: bool = True) -> None:
    """Serve the playground for *catalogue* until Ctrl-C (the command's work, and
    :func:`equilibrist.web.play`'s): bind, warm the first system up, print the address.

    *first*: the system a new page starts with (default: the cart-pole, else the first).
    """
    import uvicorn

    from equilibrist.web.app import create_app

    if first is not None:
        catalogue.check(first)  # a system that cannot be played is one line, before the port
    sock = bind(host, port)  # a port that cannot be had is said at once, before the warm-up
    bound_port = sock.getsockname()[1]
    try:
        # Requests must name this server (its loopback names, or --host): no DNS rebinding.
        app = create_app(catalogue, system=first, host=host, port=bound_port)
    except BaseException:
        sock.close()
        raise
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{bound_port}/"
    if not is_loopback(host):
        print(f"equilibrist: warning: the playground is bound to {host}: anyone who can "
              "reach this machine can use it (it has no login)", file=sys.stderr)
    print(f"equilibrist playground at {url}  (Ctrl-C to stop)", flush=True)
    config = uvicorn.Config(app, log_level="warning", ws_max_size=4 * 1024 * 1024,
                            lifespan="off", timeout_graceful_shutdown=2)
    server = uvicorn.Server(config)
    if browser:
        threading.Thread(target=_open_browser, args=(url, server), daemon=True).start()
    # uvicorn shuts down on Ctrl-C (closing every socket and the port), then raises the
    # signal again: the command line's own handler ends it with its one line (exit 130).
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
    print("equilibrist: playground stopped", file=sys.stderr)


def _open_browser(url: str, server: object) -> None:
    """Open *url* once the server listens, where a browser exists (never fails the command)."""
    import time
    import webbrowser

    for _ in range(100):
        if getattr(server, "started", False):
            break
        time.sleep(0.05)
    if not graphical():
        return  # a console browser would take the terminal over: the printed address is enough
    # No browser on this machine: the printed address is enough.
    with contextlib.suppress(webbrowser.Error):
        webbrowser.get().open(url)


def graphical() -> bool:
    """Whether a browser window can open here (Linux without a display has none)."""
    import os

    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))

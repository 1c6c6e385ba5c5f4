"""``--controller none``: the open loop (the inputs at the operating point)."""

from __future__ import annotations

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest


def build(request: ControllerRequest) -> None:
    return None


KIND = ControllerKind(
    name="none", label="Off", help="the open loop", build=build, open_loop=True,
    surfaces=frozenset({"simulate", "design", "export", "playground"}), order=90,
)

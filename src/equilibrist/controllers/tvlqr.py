"""``--controller tvlqr``: track a planned trajectory (``equilibrist trajopt``), then balance."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.control.kinds import ControllerKind, ControllerRequest, Option

if TYPE_CHECKING:
    from equilibrist.control.controller import NonlinearController


def build(request: ControllerRequest) -> NonlinearController:
    from equilibrist.control.tvlqr import build_request

    return build_request(request)


KIND = ControllerKind(
    name="tvlqr", label="Time-varying LQR (tracks a plan)",
    help="track --trajectory (a plan of 'equilibrist trajopt'), then balance",
    build=build,
    options=(Option("--trajectory", "with --controller tvlqr: the plan to track "
                    "('equilibrist trajopt --out')", metavar="FILE.npz"),),
    surfaces=frozenset({"simulate", "export"}), task="swingup", order=50,
)

"""``--controller swingup``: energy pumping from hanging, then the catch and a balancing LQR."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest, Option
from equilibrist.controllers.tvlqr import BALANCES

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System


def applies(system: System) -> str | None:
    from equilibrist.control.swingup import swingup_laws
    from equilibrist.tasks import task_names

    if "swingup" not in task_names(system):
        return f"{system.key} has no swing-up: it has no hanging position to swing up from"
    if system.spec.swingup is None:
        return f"{system.key} has no swing-up law: it exists for {', '.join(swingup_laws())}"
    return None


def build(request: ControllerRequest) -> NonlinearController:
    from equilibrist.control.swingup import swingup

    system = request.system
    return swingup(system, design=request.design(),
                   balance=str(request.options.get("balance", "lqr")))


KIND = ControllerKind(
    name="swingup", label="Swing-up (energy pumping, then LQR)",
    help="pump energy from hanging, catch near upright and balance (--balance lqr|lqg)",
    build=build,
    options=(Option("--balance", "what balances after --controller swingup's catch (default lqr)",
                    choices=BALANCES),),
    applies=applies, task="swingup", from_any_state=True, order=30,
)

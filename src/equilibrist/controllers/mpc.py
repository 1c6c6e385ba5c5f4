"""``--controller mpc``: constrained MPC solved by DAQP compiled with its driver (Kalman filter
in front where needed)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest, Option

if TYPE_CHECKING:
    from equilibrist.control.mpc_runtime import MPCRuntime


def _horizon(text: str) -> int:
    value = int(text)
    if value < 1 or str(value) != text.strip():
        raise ValueError(text)
    return value


def build(request: ControllerRequest) -> MPCRuntime:
    from equilibrist.control.mpc import mpc
    from equilibrist.control.mpc_problem import HORIZON

    opts = dict(request.options)
    horizon = opts.get("horizon")
    ctrl = mpc(request.system, design=request.design(),
               horizon=HORIZON if horizon is None else int(horizon),
               estimator=opts.get("estimator"))
    return ctrl.runtime()


def check_export(request: ControllerRequest) -> None:
    """The horizon the export can hold, before the QP is built."""
    from equilibrist.control.mpc_problem import HORIZON
    from equilibrist.export.mpc_c import check_horizon

    check_horizon(request.system, request.options.get("horizon", HORIZON))


KIND = ControllerKind(
    name="mpc", label="MPC (constrained, DAQP)",
    help="constrained MPC (DAQP), the LQR's move where no constraint binds",
    build=build,
    options=(Option("--horizon", "prediction horizon of --controller mpc [samples] (default 30)",
                    parse=_horizon, expected="a whole number of samples >= 1", metavar="N"),),
    check_export=check_export, solves_qp=True, order=40,
)

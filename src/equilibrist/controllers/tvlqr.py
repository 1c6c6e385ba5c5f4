"""``--controller tvlqr``: track a planned trajectory (``equilibrist trajopt``), then balance."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest, Option

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController

#: What ``--balance`` takes (this kind's and the swing-up's): the full measured state
#: (``lqr``) or the design's outputs through the estimator (``lqg``). The same tuple as
#: :data:`equilibrist.control.nonlinear.BALANCES`, which the controllers check against (a
#: test holds them equal): written here too because listing the kinds imports no numerics,
#: and importing ``equilibrist.control`` does.
BALANCES = ("lqr", "lqg")
#: What ``--catch`` takes: hand over inside the catch region before the plan ends, or not.
CATCHES = ("on", "off")
#: What ``--wrap`` takes: the angles' deviations modulo a turn, or as they are.
WRAPS = ("on", "off")
#: What ``--rates`` takes: the measured rates, or rates differenced from the measured angles.
#: The same tuple as :data:`equilibrist.control.tvlqr.RATES` (listing the kinds imports no
#: numerics).
RATES = ("measured", "differenced")
#: What ``--friction-compensation`` takes: add the model's friction torque on the actuated
#: joints to the command (on), or not (off, the default).
COMPENSATIONS = ("on", "off")


def build(request: ControllerRequest) -> NonlinearController:
    from equilibrist.control.tvlqr import build_request

    return build_request(request)


KIND = ControllerKind(
    name="tvlqr", label="Time-varying LQR (tracks a plan)",
    help="track --trajectory (a plan of 'equilibrist trajopt'), then balance (--balance lqr|lqg)",
    build=build,
    options=(Option("--trajectory", "with --controller tvlqr: the plan to track "
                    "('equilibrist trajopt --out')", metavar="FILE.npz"),
             Option("--balance", "with --controller tvlqr: the full state (lqr, default) or the "
                    "design's outputs through its Kalman filter (lqg)", choices=BALANCES),
             Option("--catch", "with --controller tvlqr: balance as soon as the state enters the "
                    "balancing LQR's catch region (on, default), or track the plan to its end "
                    "(off)", choices=CATCHES),
             Option("--wrap", "with --controller tvlqr --balance lqr: compare the angles modulo "
                    "a turn (on), so a rig that swung over is caught upright again, or as they "
                    "are (off, default)", choices=WRAPS),
             Option("--rates", "with --controller tvlqr --balance lqr: the measured rates "
                    "(measured, default) or rates differenced from the measured angles, "
                    "(3 q_k - 4 q_k-1 + q_k-2) / (2 T), as a rig computes them from its encoders "
                    "(differenced)", choices=RATES),
             Option("--friction-compensation", "with --controller tvlqr --balance lqr: add the "
                    "model's own friction torque on the actuated joints (their damping and "
                    "Coulomb friction, at the rates the law uses) to the command, the gains "
                    "designed for the plant it leaves (on), or not (off, default)",
                    choices=COMPENSATIONS),
             Option("--design-torque-response", "with --controller tvlqr --balance lqr: the "
                    "motor's first-order lag the tracker compensates, as the rig's "
                    "--torque-response k per period (0 < k < 2) or a time constant (20ms, "
                    "0.02s): the plan's torque led by the lag's inverse, the gains of the model "
                    "with the torque state (none by default)", metavar="K|TC")),
    surfaces=frozenset({"simulate", "export", "study", "playground"}), task="swingup", planned=True,
    order=50,
)

"""``equilibrist design``: LQR, Kalman filter and reference gain, at the canonical point or --at another."""

from __future__ import annotations

import argparse

from equilibrist.cli import common
from equilibrist.errors import UsageError

_EPILOG = """\
Weights are diagonals, comma-separated: --q one value per state, --r one per
input, --qn one per state (QN = diag(qn), G = I), --rn one per measured
output (a list that starts with a minus sign is written --q=-1,2,...).
Defaults: Bryson's rule from the system's design scales and the spec's
sensor and process noise.

--json prints every matrix as a list of rows and every pole as
{"re": ..., "im": ...} (also when real); numbers that are not finite (an
infinite time constant) are null. Keys include K, S, poles, Kf, P, Kc
(null when the tracked output has zero DC gain; kc_note says why),
estimator_poles, Q, R, QN, RN, G, Qd, Rd, plant, discrete, margins,
lqr_margins, and (with --rate) "controller": the chosen controller as the
one linear form the simulator runs and the C export writes (kind, form, Ac,
By, Br, Bu, Cc, Dy, Dr).

margins are those of the loop as implemented, broken at the plant input
(null with several inputs): for lqg the compensator, its Kalman filter fed
its own command, in series with the plant, in the design's timebase
(discrete at --rate); for lqr the state feedback. lqr_margins are the state
feedback's alone, K (sI - A)^-1 B: an LQG has no guaranteed margins and its
loop's are usually well below them. With --design-delay each is the loop as
it runs: the controller holding its record of the commands in flight, fed
its own command, with the plant and its delay line; with
--design-velocity-filter the LQG's loop runs through the rig's filter.
equilibrist.control.loop_at_input(d) is that loop as a python-control system.

--at STATE=VALUE designs at the equilibrium with those states (the others
solved), e.g. --at theta=3.14159 for a pendulum hanging down.
--controller lqr|lqg (default lqg) names the controller whose form --json
shows; swingup and mpc are designed by their own modules when installed; a
controller that does not apply to the system is refused in one line.
"""



def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "design",
        help="design LQR + Kalman (LQG) controllers at an operating point",
        description="Design an LQR state feedback, a Kalman estimator and a reference gain "
        "for a system at its canonical operating point, continuous or sampled at --rate.",
        epilog=_EPILOG)
    common.add_system(p)
    p.add_argument("--rate", metavar="HZ", help="sample rate of a discrete design [Hz]")
    common.add_design_options(p)
    common.add_controller(p, "design", default="lqg",
                          help="the controller to design (default lqg: the LQR and the Kalman "
                          "filter)")
    common.add_set(p)
    common.add_params(p)
    common.add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.control.design import design

    system = common.load_system(args)
    rate = None if args.rate is None else common.parse_number(args.rate, "--rate")
    from equilibrist.controllers import kinds

    kind = args.controller
    record = kinds.get(kind, "design")
    if record.open_loop:
        raise UsageError(f"--controller {kind} is the open loop: there is nothing to "
                                "design")
    options = common.controller_options(args, kind, "design")
    if not record.linear:
        from equilibrist.control.controller import describe_controller

        request = kinds.ControllerRequest(system=system, rate=rate,
                                          design_options=common.design_options(args),
                                          options=options)
        built = record.make(request)
        info = {"kind": kind} if built is None else describe_controller(built, kind)
        if args.json:
            common.print_json(info)
        else:
            print(f"{system.key}: {kind} controller")
            for key, value in info.items():
                print(f"  {key}: {value}")
        return 0
    result = design(system, rate=rate, **common.design_options(args))
    if options.get("design_delay") is not None or options.get("design_velocity_filter") is not None:
        from equilibrist.control.design import kind_design

        if rate is None:  # the kind's options: the design it builds on
            flag = "--design-delay" if options.get("design_delay") is not None \
                else "--design-velocity-filter"
            raise UsageError(f"{flag} needs --rate: it designs a sampled loop")
        result = kind_design(result, system, options)
    if args.json:
        out = result.to_dict(controller=kind)
        if result.rate is not None:
            from equilibrist.control.linear import LinearController

            out["controller"] = LinearController.from_design(result, kind=kind).describe()
        common.print_json(out)
    else:
        print(result.summary(controller=kind))
    return 0

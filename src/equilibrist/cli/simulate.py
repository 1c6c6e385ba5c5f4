"""``equilibrist simulate``: one closed-loop run as a rig runs it.

The flags ``--controller --duration --rate --x0 --push --noise --seed --set
--q --r --qn --rn --outputs --out --json`` are a contract with scripts
outside the project; ``equilibrist batch`` takes the same ones.
"""

from __future__ import annotations

import argparse
import math
import os
import stat
import sys
from typing import TYPE_CHECKING, Any

from equilibrist.cli import common
from equilibrist.errors import UsageError

if TYPE_CHECKING:
    from collections.abc import Mapping

    from equilibrist.control.controller import AnyController
    from equilibrist.numeric.system import System
    from equilibrist.sim.events import Event
    from equilibrist.sim.result import SimResult
    from equilibrist.sim.signals import PRBS, Chirp


_EPILOG = """\
The run: the nonlinear plant integrated with RK4 (or another --integrator)
at --physics-step, which must divide the control period 1/--rate; the
controller designed for that rate (LQR on the full state, or LQG: a discrete
Kalman filter on the measured --outputs) with zero-order hold and the
actuator's limits; noise with the design's covariances (--noise on, seeded by
--seed). It stops with fell = true when a state leaves the system's region.

--x0 NAME=VALUE: initial state components (absolute; the rest at the
operating point). --push T:VALUE[:DURATION]: a force (torque) of VALUE in
the first input's unit added to that input's channel from T for DURATION
seconds (default 0.1 s), beside the actuator (not saturated).
--kick T:STATE=VALUE: add VALUE to a state at T (e.g. theta_dot=0.5).
--change T:NAME=VALUE: a plant parameter changes at T (the controller keeps
its design). --reference step:V[@T] | ramp:SLOPE[@T] | square:AMP:PERIOD |
file:PATH: track it with the reference gain K_c (lqr or lqg).
Weights --q --r --qn --rn are comma-separated diagonals as in 'equilibrist
design'. A reference must stay finite and within 1e12 times the tracked
state's region of the operating point over the run. --json prints the
summary metrics (fell, fell_at, settling_time, overshoot, peak_command (the
largest command, before the actuator's limits), peak_input (the largest
input that acted), rms_input, time_saturated, final_error,
estimation_error_rms, ...). --out FILE.npz saves the run (FILE.csv exports
a table that starts with the log 'equilibrist identify' reads: t, the inputs,
the measured outputs; then the true states and the rest).

--excite SIGNAL (an identification experiment) adds a signal to the
controller's command, before the actuator's limits, on every input:
chirp:AMP:F0:F1[:SWEEP], a sine of amplitude AMP (the input's unit) whose
frequency rises linearly from F0 to F1 Hz over SWEEP seconds (default the
whole run); prbs:AMP:PERIOD, +-AMP switching at multiples of PERIOD seconds
by an 11-bit maximal-length shift register whose bits are fixed by --seed.

Work is bounded: a run needing more than --max-steps physics steps (default
1e10; duration x rate x physics steps per period) is refused before it
starts, with the count and the least time it would take; --max-steps N (or
inf) asks for it anyway. Ctrl-C stops a run within about a second, with or
without the progress bar.
"""


def add_run_options(p: argparse.ArgumentParser) -> None:
    """The options shared by ``simulate`` and ``batch``."""
    common.add_system(p)
    common.add_controller(p, "simulate", default=None,
                          help="the controller (default lqg, none for a system without input); "
                          "one that does not apply to the system is refused")
    p.add_argument("--duration", default="5", metavar="S", help="seconds to simulate (default 5)")
    p.add_argument("--rate", metavar="HZ",
                   help="controller sample rate [Hz] (default: the system's control rate)")
    p.add_argument("--physics-step", metavar="S",
                   help="integration step [s], dividing 1/rate (default: at most 1 ms)")
    from equilibrist.sim import integrators

    p.add_argument("--integrator", choices=integrators.names(), default=integrators.DEFAULT,
                   help=integrators.help_text())
    p.add_argument("--plant", choices=("nonlinear", "linear"), default="nonlinear",
                   help="the system's own dynamics (default) or its linearization")
    common.add_items(p, "--x0", marker="=", metavar="NAME=VALUE",
                   help="initial state components")
    common.add_items(p, "--push", marker=":", metavar="T:VALUE",
                   help="a force pulse VALUE on the first input at T (T:VALUE[:DURATION])")
    common.add_items(p, "--kick", marker="=", metavar="T:STATE=VALUE",
                   help="add VALUE to STATE at time T")
    common.add_items(p, "--change", marker="=", metavar="T:NAME=VALUE",
                   help="change a plant parameter at time T")
    p.add_argument("--delay", action="store_true", help="apply each command one sample late")
    p.add_argument("--noise", choices=("on", "off"), default="on",
                   help="process and sensor noise (default on)")
    p.add_argument("--seed", default="0", metavar="N", help="noise seed (default 0)")
    p.add_argument("--reference", metavar="SIGNAL",
                   help="reference of the tracked output: step:V[@T], ramp:S[@T], square:A:P, file:PATH")
    common.add_set(p)
    common.add_params(p)
    common.add_design_options(p)
    p.add_argument("--out", metavar="FILE", help="save the result (.npz; .csv exports a table)")
    p.add_argument("--max-steps", metavar="N",
                   help="the most physics steps the command may take, over all runs (default "
                   f"{_setup_default_steps():.0e}; 'inf' for no bound): more is refused before "
                   "anything runs, with the count and an estimate of the time")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    common.add_json(p)


def _setup_default_steps() -> float:
    from equilibrist.sim.budget import DEFAULT_MAX_STEPS

    return float(DEFAULT_MAX_STEPS)


def parse_max_steps(text: str | None) -> float | None:
    """--max-steps as a bound (None: no bound), the default without the option."""
    if text is None:
        return _setup_default_steps()
    if text.strip().lower() in ("inf", "infinity"):
        return None
    v = common.parse_number(text, "--max-steps")
    if v < 1:
        raise UsageError(f"--max-steps {text}: expected a number of physics steps >= 1 "
                                "(or inf for no bound)")
    return v


def check_out(args: argparse.Namespace, what: str) -> None:
    """Refuse a bad --out name before anything runs (an empty one is not 'no file')."""
    if args.out is None:
        return
    from pathlib import Path

    from equilibrist.sim.result import check_result_path

    if not args.out.strip():
        raise UsageError(f"--out {args.out!r}: expected a file name (NAME.npz or NAME.csv)")
    check_result_path(Path(args.out), what)
    common.check_output_path(args.out, "--out")  # its folder exists: none is created


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "simulate",
        help="simulate a closed loop with a digital controller, noise and saturation",
        description="Simulate one closed-loop run of a system as a rig runs it.",
        epilog=_EPILOG)
    add_run_options(p)
    common.add_rig_options(p)
    p.add_argument("--excite", metavar="SIGNAL", help="add an excitation to the command: "
                   "chirp:AMP:F0:F1[:SWEEP] or prbs:AMP:PERIOD (see below)")
    from equilibrist.viz.cli_hooks import add_output_options

    add_output_options(p)
    p.set_defaults(func=run)


# -- parsing ---------------------------------------------------------------------


def _seed(text: str) -> int:
    return common.parse_whole(text, "--seed", minimum=0)


def _split_time(item: str, option: str) -> tuple[float, str]:
    t, sep, rest = item.partition(":")
    if not sep or not rest:
        raise UsageError(f"{option} {item!r}: expected T:...")
    time = common.parse_number(t, f"{option} time")
    if time < 0:
        raise UsageError(f"{option} {item!r}: the time must be >= 0")
    return time, rest


def parse_events(args: argparse.Namespace, system: System) -> list[Event]:
    """The --push, --kick and --change items as simulation events."""
    from equilibrist.sim.events import Kick, ParameterChange, Pulse

    events: list[Event] = []
    for item in args.push:
        t, rest = _split_time(item, "--push")
        parts = rest.split(":")
        if len(parts) > 2:
            raise UsageError(f"--push {item!r}: expected T:VALUE[:DURATION]")
        value = common.parse_number(parts[0], "--push value")
        duration = 0.1 if len(parts) == 1 else common.parse_positive(parts[1], "--push duration")
        events.append(Pulse(t, value, duration))
    for item in args.kick:
        t, rest = _split_time(item, "--kick")
        (name, text), = common.parse_assignments([rest], "--kick").items()
        events.append(Kick(t, name, common.parse_number(text, f"--kick {name}")))
    for item in args.change:
        t, rest = _split_time(item, "--change")
        values = common.parse_assignments(rest.split(","), "--change")
        events.append(ParameterChange(
            t, {k: common.parse_number(v, f"--change {k}") for k, v in values.items()}))
    return events


def parse_excitation(args: argparse.Namespace) -> Chirp | PRBS | None:
    """The --excite signal (None without one)."""
    if args.excite is None:
        return None
    from equilibrist.sim.signals import parse_excitation as parse

    return parse(args.excite, seed=_seed(args.seed))


def parse_x0(items: list[str]) -> dict[str, float]:
    raw = common.parse_assignments(items, "--x0")
    return {k: common.parse_number(v, f"--x0 {k}") for k, v in raw.items()}


def show_progress(args: argparse.Namespace) -> bool:
    """A bar on stderr, except when --json output goes to a pipe (or --no-progress)."""
    if args.no_progress:
        return False
    return not (args.json and _stdout_is_pipe())


def _stdout_is_pipe() -> bool:
    try:
        return stat.S_ISFIFO(os.fstat(sys.stdout.fileno()).st_mode)
    except (OSError, ValueError, AttributeError):  # no real file behind stdout (a test's capture)
        return True


def controller_name(args: argparse.Namespace, system: System) -> str:
    """The kind the options name: ``--controller``, else the trained network of ``--policy
    FILE`` alone, else the LQG (the open loop for a system without input)."""
    return str(args.controller or ("policy" if getattr(args, "policy", None)
                                   else "lqg" if system.n_inputs else "none"))


def build_run(args: argparse.Namespace) -> tuple[System, dict[str, Any]]:
    """The system and the keyword arguments of ``simulate`` from the options."""
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.signals import parse_signal

    system = common.load_system(args)
    duration = common.parse_positive(args.duration, "--duration")
    rate = (common.parse_positive(args.rate, "--rate") if args.rate is not None
            else float(system.spec.control_rate))
    step = None if args.physics_step is None else common.parse_positive(args.physics_step, "--physics-step")
    name = controller_name(args, system)
    from equilibrist.controllers import kinds

    kind = kinds.get(name, "simulate")
    reference = None if args.reference is None else parse_signal(args.reference)
    noise_on = args.noise == "on"
    design_kwargs = common.design_options(args)
    outputs = design_kwargs.pop("outputs")
    request = kinds.ControllerRequest(
        system=system, rate=rate, design_options={"outputs": outputs, **design_kwargs},
        tracking=reference is not None, options=common.controller_options(args, name, "simulate"),
    )
    controller: AnyController | None = None
    noise = None
    if kind.open_loop:
        for flag in ("q", "r", "qn", "rn"):
            if getattr(args, flag) is not None:
                raise UsageError(f"--{flag} needs a controller (--controller lqr or lqg)")
        if noise_on:
            noise = Noise.from_spec(system, outputs=outputs, rate=rate)
    else:
        from equilibrist.control.controller import measured_outputs

        controller = kind.make(request)
        if noise_on:
            if kind.noise == "design":
                noise = Noise.from_design(request.design())
            else:
                noise = Noise.from_spec(system, outputs=measured_outputs(controller) or outputs,
                                        rate=rate)
        outputs = None
    options: dict[str, Any] = {
        "controller": controller,
        "duration": duration,
        "rate": rate,
        "physics_step": step,
        "integrator": args.integrator,
        "plant": args.plant,
        "delay": args.delay,
        "noise": noise,
        "seed": _seed(args.seed),
        "reference": reference,
        "events": parse_events(args, system),
        "outputs": outputs,
        "max_steps": parse_max_steps(args.max_steps),
    }
    rig = common.rig_option(args)
    if rig is not None:
        options["rig"] = rig
    if kind.task is not None and kind.task in _tasks(system):
        # A swing-up starts hanging: only the task's region (the cart's track) ends it.
        from equilibrist.tasks import get_task

        options["region"] = dict(get_task(system, kind.task).region)
    return system, options


def _tasks(system: System) -> tuple[str, ...]:
    from equilibrist.tasks import task_names

    return task_names(system)


def start_of(options: Mapping[str, object], x0: dict[str, float]) -> dict[str, float]:
    """The run's start: --x0, else where the controller's plan starts (a tracked trajectory)."""
    if x0:
        return x0
    ctrl = options.get("controller")
    start = getattr(ctrl, "settings", {}).get("start") if ctrl is not None else None
    return dict(start) if isinstance(start, dict) else x0


def _fmt(v: object) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.6g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_fmt(x)}" for k, x in v.items()) or "-"
    return str(v)


def run_metrics(result: SimResult) -> dict[str, object]:
    """The run's metrics: ``peak_command`` (before the actuator's limits) beside
    ``peak_input`` (the largest input that acted), each named for what it is."""
    return dict(result.metrics())


def run(args: argparse.Namespace) -> int:
    from equilibrist.sim.run import simulate

    check_out(args, "the run")
    system, options = build_run(args)
    result = simulate(system, x0=start_of(options, parse_x0(args.x0)), progress=show_progress(args),
                      excitation=parse_excitation(args), **options)
    saved = result.save(args.out) if args.out is not None else None
    from equilibrist.viz.cli_hooks import handle_outputs

    handle_outputs(args, result, system=system)
    metrics = run_metrics(result)
    if args.json:
        out = dict(metrics)
        if "rig" in result.settings:
            out["rig"] = result.settings["rig"]
        if saved is not None:
            out["saved"] = str(saved)
        common.print_json(out)
        return 0
    rows = [(k, _fmt(v)) for k, v in metrics.items() if k not in ("system", "seed")]
    print(f"{system.key}: {'fell at ' + _fmt(result.fell_at) + ' s' if result.fell else 'stayed up'}")
    print(common.format_table(("metric", "value"), rows))
    if saved is not None:
        print(f"saved {saved}")
    return 0

"""``equilibrist dynamics``: evaluate ``x_dot = f(x, u)`` at one point."""

from __future__ import annotations

import argparse

from equilibrist.cli import common
from equilibrist.errors import UsageError


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("dynamics", help="evaluate x_dot = f(x, u) at a state and input")
    common.add_system(p)
    p.add_argument("--state", required=True, metavar="V1,V2,...", help="state values in state order")
    p.add_argument("--input", metavar="U1,...", help="input values in input order")
    common.add_set(p)
    common.add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    system = common.load_system(args)
    x = common.parse_vector(args.state, f"--state ({', '.join(system.state_names)})", system.n_states)
    if x is None:
        raise UsageError("--state is required")
    if system.n_inputs and args.input is None:
        raise UsageError(
            f"{system.key} needs --input with {system.n_inputs} value(s) ({', '.join(system.input_names)})"
        )
    u = common.parse_vector(args.input, f"--input ({', '.join(system.input_names) or 'none'})",
                            system.n_inputs) if args.input is not None else []
    xdot = system.f(x, u)
    if args.json:
        common.print_json({
            "system": system.key,
            "states": list(system.state_names),
            "inputs": list(system.input_names),
            "x": x,
            "u": u,
            "xdot": xdot,
        })
        return 0
    rows = [[n, f"{v:.6g}", f"{d:.6g}", unit]
            for n, v, d, unit in zip(system.state_names, x, xdot, system.state_units, strict=True)]
    print(common.format_table(["state", "value", "rate", "unit"], rows))
    return 0

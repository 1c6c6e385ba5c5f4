"""Argument helpers shared by the subcommands."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from equilibrist import numbers
from equilibrist.errors import ParameterError, UsageError

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


STRAYS = "_stray_words"


class ItemsAction(argparse.Action):
    """A repeatable option taking several items (``--set m_p=2 l=0.4``).

    argparse hands such an option every word up to the next option, so a
    SYSTEM written after it (``linearize --set m_p=2 cartpole``) would be
    swallowed. Items contain ``marker`` (``=`` or ``:``); a word that does
    not is kept aside, and the command line takes it as the SYSTEM (or
    names it as out of place).
    """

    def __init__(self, option_strings: Sequence[str], dest: str, *, marker: str, **kwargs: Any) -> None:
        kwargs.setdefault("nargs", "+")
        kwargs.setdefault("default", [])
        super().__init__(option_strings, dest, **kwargs)
        self.marker = marker

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        items = list(getattr(namespace, self.dest, None) or [])
        strays = list(getattr(namespace, STRAYS, None) or [])
        for k, value in enumerate(values):
            # The first word is the option's own, right or wrong: its parser
            # says what is wrong with it.
            if k == 0 or self.marker in value:
                items.append(value)
            else:
                strays.append((option_string, value))
        setattr(namespace, self.dest, items)
        setattr(namespace, STRAYS, strays)


def add_items(parser: argparse.ArgumentParser, option: str, *, marker: str, metavar: str,
              help: str, dest: str | None = None) -> None:
    """A repeatable option of several ``marker``-separated items (see :class:`ItemsAction`)."""
    kwargs: dict[str, Any] = {"dest": dest} if dest else {}
    parser.add_argument(option, action=ItemsAction, marker=marker, metavar=metavar, help=help, **kwargs)


def take_strays(args: argparse.Namespace) -> None:
    """Give a word that followed a list option to SYSTEM, or refuse it in one line."""
    strays = list(getattr(args, STRAYS, None) or [])
    if strays and hasattr(args, "system") and args.system is None:
        args.system = strays.pop(0)[1]
    if strays:
        option, word = strays[0]
        raise UsageError(f"{word!r} after {option} is not one of its items; SYSTEM goes before the options")
    if getattr(args, "needs_system", False) and args.system is None:
        raise UsageError("the following arguments are required: SYSTEM")


def command(sub: argparse._SubParsersAction[argparse.ArgumentParser], name: str, *, help: str,
            description: str, epilog: str) -> argparse.ArgumentParser:
    """A command's parser whose description and epilog keep their lines as written."""
    return sub.add_parser(name, help=help, description=description, epilog=epilog,
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def add_system(parser: argparse.ArgumentParser) -> None:
    parser.set_defaults(needs_system=True)
    parser.add_argument(
        "system", metavar="SYSTEM", nargs="?", default=None,
        help="a system name (see 'equilibrist systems'), or the path of your own system: "
             "a .py file, an MJCF model (.xml) or a URDF (.urdf)",
    )


def parameter_names(name: str) -> set[str]:
    """Every parameter name of the system (or family, or system file) *name*."""
    from equilibrist.systems import files, registry

    if files.looks_like_path(name):
        return set(files.from_file(name).spec.parameter_names)
    return {p for entry in registry.lookup_family(name).values() for p in entry.spec.parameter_names}


def add_set(parser: argparse.ArgumentParser) -> None:
    add_items(parser, "--set", dest="settings", marker="=", metavar="NAME=VALUE",
              help="set parameters, or a variant option such as euler=xyz (repeatable)")


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON for scripts")


def parse_number(text: str, what: str) -> float:
    """*text* as a finite decimal number (surrounding blanks ignored); anything else, such as
    ``1_0``, is refused in one line naming *what*."""
    word = text.strip()
    if not (numbers.is_decimal(word) or numbers.NOT_FINITE.fullmatch(word)):
        raise UsageError(f"{what}: {text!r} is not a number (expected a decimal such as "
                         "0.25, -3 or 1e-3)")
    value = float(word)
    if not math.isfinite(value):
        raise ParameterError(f"{what}: {text} is not a finite number")
    return value


def parse_positive(text: str, option: str) -> float:
    """*text* as a finite number above zero, else one line naming *option*."""
    value = parse_number(text, option)
    if value <= 0:
        raise UsageError(f"{option} must be positive, got {text}")
    return value


def parse_assignments(items: Iterable[str], option: str) -> dict[str, str]:
    """``["a=1", "b=2"]`` -> ``{"a": "1", "b": "2"}``; malformed items are refused."""
    out: dict[str, str] = {}
    for item in items:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise UsageError(f"{option} {item!r}: expected NAME=VALUE")
        if name in out:
            raise UsageError(f"{option} gives {name} twice")
        out[name] = value
    return out


def parse_vector(text: str | None, what: str, n: int | None = None) -> list[float] | None:
    """``"1,2,3"`` -> ``[1.0, 2.0, 3.0]``, checking count and finiteness."""
    if text is None:
        return None
    parts = [p for p in text.split(",")]
    if any(not p.strip() for p in parts):
        raise UsageError(f"{what} {text!r}: expected comma-separated numbers")
    values = [parse_number(p.strip(), what) for p in parts]
    if n is not None and len(values) != n:
        raise UsageError(f"{what} has {len(values)} values, expected {n}")
    return values


def system_settings(name: str, items: Sequence[str]) -> dict[str, object]:
    """The ``--set`` items as keyword settings of :func:`get_system`."""
    raw = parse_assignments(items, "--set")
    settings: dict[str, object] = {}
    known = parameter_names(name)
    for key, value in raw.items():
        # Unknown names go through as they are: the system's validation
        # names them and suggests the nearest parameter.
        settings[key] = parse_number(value, f"--set {key}") if key in known else value
    return settings


def add_params(parser: argparse.ArgumentParser) -> None:
    """``--params FILE.json``: parameter values from a file (``identify --out``)."""
    parser.add_argument("--params", metavar="FILE.json",
                        help="parameter values from a JSON file (as 'equilibrist identify --out' "
                        "writes); --set values override them")


def load_system(args: argparse.Namespace) -> System:
    """The system named on the command line with its ``--params`` and ``--set`` values."""
    from equilibrist.numeric.lookup import get_system

    parameter_names(args.system)  # unknown names and bad files fail before parsing values
    settings: dict[str, object] = {}
    if getattr(args, "params", None) is not None:  # only commands given add_params have it
        from equilibrist.ident.params import read_params

        settings.update(read_params(args.params, system=args.system))
    settings.update(system_settings(args.system, args.settings))
    return get_system(args.system, **settings)


def add_system_option(parser: argparse.ArgumentParser) -> None:
    """``--system SYSTEM``: the system a data file came from, named by the user."""
    parser.add_argument(
        "--system", metavar="SYSTEM",
        help="the system the file came from (a name, or your own system file): needed when the "
        "file names a Python system file, which a data file never runs by itself; checked to be "
        "the same definition as the file's")


def named_system(name: str | None) -> System | None:
    """The system given by ``--system`` (run now: the user named it), or ``None``."""
    if name is None:
        return None
    from equilibrist.numeric.lookup import get_system

    return get_system(name)


def to_jsonable(obj: object) -> object:
    """numpy arrays and scalars to lists and floats; NaN and infinities to None."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        if np.iscomplexobj(obj):
            return [to_jsonable(v) for v in obj.tolist()]
        return to_jsonable(obj.tolist())
    if isinstance(obj, complex):
        return {"re": to_jsonable(obj.real), "im": to_jsonable(obj.imag)}
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def check_output_path(text: str, option: str) -> Path:
    """The output file *text* of *option* (``--out``, ``--plot``) as a Path, checked before
    any work: a name is given, it is not a folder, and its folder exists (equilibrist creates
    no missing folder; :func:`equilibrist.atomic.check_output`). Each refusal is one line
    naming the option and the path (:class:`~equilibrist.atomic.OutputError`, exit status 2)."""
    from equilibrist.atomic import OutputError, check_output

    if not text.strip():
        raise UsageError(f"{option} {text!r}: expected a file name")
    path = check_output(text, what=option)
    if path.is_dir():
        raise OutputError(f"{option} {path} is a folder: name a file")
    return path


def print_json(obj: object) -> None:
    json.dump(to_jsonable(obj), sys.stdout, indent=2)
    sys.stdout.write("\n")


def format_matrix(mat: np.ndarray, rows: Sequence[str], cols: Sequence[str], *, width: int = 11) -> str:
    """A labelled matrix as aligned text."""
    label = max([len(r) for r in rows] + [1])
    width = max([width] + [len(c) + 2 for c in cols])  # long names keep their columns apart
    head = " " * (label + 2) + "".join(f"{c:>{width}}" for c in cols)
    lines = [head]
    for r, row in zip(rows, np.atleast_2d(mat), strict=False):
        lines.append(f"  {r:<{label}}" + "".join(f"{v:>{width}.5g}" for v in row))
    return "\n".join(lines)


def format_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    cells = [[str(h) for h in header]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    out = []
    for k, r in enumerate(cells):
        out.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
        if k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)


def parse_whole(text: str, option: str, minimum: int = 1) -> int:
    """*text* as a whole number >= *minimum* (decimal digits: int() would take ``1_0``),
    else one line naming the option."""
    if not numbers.is_whole(text):
        raise UsageError(f"{option} {text!r}: expected a whole number >= {minimum}")
    v = int(text)
    if v < minimum:
        raise UsageError(f"{option} {text!r}: expected a whole number >= {minimum}")
    return v


def parse_names(text: str | None, option: str) -> tuple[str, ...] | None:
    """``"x,theta"`` -> ``("x", "theta")``; empty items are refused."""
    if text is None:
        return None
    parts = tuple(t.strip() for t in text.split(","))
    if not all(parts):
        raise UsageError(f"{option} {text!r}: expected comma-separated names")
    return parts


# The names of equilibrist.control.discretize.METHODS and kalman.FORMS,
# written out so that building the parser does not import scipy.
DISCRETIZATIONS = ("zoh", "euler")
KALMAN_FORMS = ("current", "predictor")


def add_design_options(parser: argparse.ArgumentParser) -> None:
    """The weights and choices of a controller design (design, simulate, export)."""
    parser.add_argument("--q", metavar="Q1,Q2,...", help="LQR state weights, one per state")
    parser.add_argument("--r", metavar="R1,...", help="LQR input weights, one per input")
    parser.add_argument("--qn", metavar="QN1,...", help="process noise intensities, one per state")
    parser.add_argument("--rn", metavar="RN1,...", help="measurement noise intensities, one per output")
    parser.add_argument("--outputs", metavar="NAME,...",
                        help="measured outputs (state names); the first ones are tracked")
    parser.add_argument("--discretization", choices=DISCRETIZATIONS, default="zoh",
                        help="how the plant is sampled (default zoh)")
    parser.add_argument("--kalman", choices=KALMAN_FORMS, default="current",
                        help="discrete Kalman gain form (default current)")
    add_items(parser, "--at", marker="=", metavar="STATE=VALUE",
              help="design at the equilibrium with these states (the others solved); "
              "default the canonical operating point")


def add_controller(parser: argparse.ArgumentParser, surface: str, *, default: str | None,
                   help: str) -> None:
    """``--controller`` with the registry's kinds offered on *surface* as its choices (their
    one-line helps in the help), and each of those kinds' own options
    (:mod:`equilibrist.controllers.kinds`)."""
    from equilibrist.controllers import kinds

    offered = kinds.all_kinds(surface)
    listed = "; ".join(f"{k.name}: {k.help}" for k in offered)
    parser.add_argument("--controller", choices=[k.name for k in offered], default=default,
                        help=f"{help} ({listed})")
    for opt in kinds.options(surface):
        parser.add_argument(opt.flag, metavar=opt.metavar, choices=opt.choices, default=None,
                            dest=opt.key, help=opt.help)


def controller_options(args: argparse.Namespace, kind: str, surface: str) -> dict[str, object]:
    """The options of the kind *kind* given on the command line (parsed); an option of
    another kind is refused in one line."""
    from equilibrist.controllers import kinds

    record = kinds.get(kind, surface)
    own = {o.flag for o in record.options}
    out: dict[str, object] = {}
    for opt in kinds.options(surface):
        text = getattr(args, opt.key, None)
        if text is None:
            continue
        if opt.flag not in own:
            owners = " or ".join(f"--controller {k}" for k in kinds.owners(opt.flag, surface))
            raise UsageError(f"{opt.flag} is an option of {owners}: the {kind} controller "
                             "takes none")
        for o in record.options:
            if o.flag == opt.flag:
                out[o.key] = o.value(str(text))
    return out


class DesignOptions(TypedDict, total=False):
    """Keyword arguments of :func:`equilibrist.control.design.design` (:func:`design_options`)."""

    q: list[float] | None
    r: list[float] | None
    qn: list[float] | None
    rn: list[float] | None
    outputs: tuple[str, ...] | None
    discretization: str
    kalman_form: str
    at: dict[str, float] | None


def design_options(args: argparse.Namespace) -> DesignOptions:
    """Keyword arguments of :func:`equilibrist.control.design.design` from the options."""
    return {
        "q": parse_vector(args.q, "--q"),
        "r": parse_vector(args.r, "--r"),
        "qn": parse_vector(args.qn, "--qn"),
        "rn": parse_vector(args.rn, "--rn"),
        "outputs": parse_names(args.outputs, "--outputs"),
        "discretization": args.discretization,
        "kalman_form": args.kalman,
        "at": operating_point_option(getattr(args, "at", None)),
    }


def operating_point_option(items: Sequence[str] | None) -> dict[str, float] | None:
    """``--at STATE=VALUE ...`` as ``{state: value}`` (None when not given)."""
    if not items:
        return None
    raw = parse_assignments(items, "--at")
    return {k: parse_number(v, f"--at {k}") for k, v in raw.items()}


def add_rig_options(parser: argparse.ArgumentParser) -> None:
    """A rig's effects between the plant and the controller (:mod:`equilibrist.sim.rig`),
    every one off by default."""
    group = parser.add_argument_group("rig effects (all off by default)")
    group.add_argument("--torque-response", metavar="K",
                       help="motor torque response per control period, tau = tau_prev + K "
                       "(tau_des - tau_prev) (1 immediate, below 1 a lag)")
    group.add_argument("--torque-time-constant", metavar="S",
                       help="motor torque response as a first-order lag of this time constant")
    group.add_argument("--measurement-delay", metavar="N|Ts",
                       help="measurements N control periods late, or T seconds (0.004s, 4ms)")
    group.add_argument("--actuation-delay", metavar="N|Ts",
                       help="commands N control periods late, or T seconds (0.004s, 4ms)")
    group.add_argument("--torque-noise", metavar="SIGMA",
                       help="white noise of this standard deviation on each input's torque")
    group.add_argument("--velocity-noise", metavar="SIGMA",
                       help="white noise of this standard deviation on the measured velocities")
    group.add_argument("--encoder-step", metavar="STEP",
                       help="encoders: positions read in steps of STEP (2*pi/4096 rad for 4096 "
                       "counts a turn), velocities by differencing them")
    group.add_argument("--velocity-filter", metavar="HZ",
                       help="first-order low-pass of the measured velocities, cutoff HZ")
    group.add_argument("--perturbations", metavar="N",
                       help="N random Gaussian torque pulses on each joint (or --perturb-joints)")
    group.add_argument("--perturb-joints", metavar="NAME,...",
                       help="the joints (coordinates) that --perturbations pushes (default all)")
    group.add_argument("--perturbation-amplitude", metavar="LOW:HIGH",
                       help="the pulses' peak torques, drawn in +-[LOW, HIGH] (default 0.5:5)")


def _delay(text: str | None, option: str) -> tuple[int, float]:
    """``N`` (control periods) or ``Ts``/``Tms`` (seconds) as (periods, seconds)."""
    if text is None:
        return 0, 0.0
    word = text.strip()
    if word.endswith("ms"):
        return 0, parse_number(word[:-2], option) / 1000.0
    if word.endswith("s"):
        return 0, parse_number(word[:-1], option)
    return parse_whole(word, option, minimum=0), 0.0


def rig_option(args: argparse.Namespace) -> Any:
    """The :class:`~equilibrist.sim.rig.Rig` the options ask for, or None (none given)."""
    from equilibrist.sim.rig import Rig

    def number(name: str, option: str) -> float | None:
        text = getattr(args, name, None)
        if text is None:
            return None
        value = parse_number(text, option)
        if value < 0:
            raise UsageError(f"{option} {text}: expected a number >= 0")
        return value

    kw: dict[str, Any] = {}
    for name in ("torque_response", "torque_time_constant", "torque_noise", "velocity_noise",
                 "encoder_step", "velocity_filter"):
        value = number(name, "--" + name.replace("_", "-"))
        if value is not None:
            kw[name] = value
    for which in ("measurement", "actuation"):
        periods, seconds = _delay(getattr(args, f"{which}_delay", None), f"--{which}-delay")
        if periods:
            kw[f"{which}_delay"] = periods
        if seconds:
            kw[f"{which}_delay_time"] = seconds
    if getattr(args, "perturbations", None) is not None:
        kw["perturbations"] = parse_whole(args.perturbations, "--perturbations", minimum=0)
    joints = parse_names(getattr(args, "perturb_joints", None), "--perturb-joints")
    if joints is not None:
        kw["perturbation_joints"] = joints
    amplitude = getattr(args, "perturbation_amplitude", None)
    if amplitude is not None:
        lo, sep, hi = amplitude.partition(":")
        if not sep:
            raise UsageError(f"--perturbation-amplitude {amplitude!r}: expected LOW:HIGH")
        kw["perturbation_amplitude"] = (parse_number(lo, "--perturbation-amplitude"),
                                        parse_number(hi, "--perturbation-amplitude"))
    rig = Rig(**kw)
    return None if rig.off else rig

"""Identified parameter files of DFKI's double pendulum (``model_parameters.yml``), as they are.

The rig's identification writes one flat YAML mapping of numbers (``m1: 0.52``, ``I1:``,
``Ir:``, ``gr:``, ``b1:``, ``cf1:``, ``tl1:``...), the names of
:mod:`equilibrist.systems.dfki_double_pendulum`'s parameters. :func:`read_model_parameters` reads such a
file into the settings of ``dfki_double_pendulum``: the variant (``robot``), every model
parameter by its own name, and the actuated joint's torque limit ``tl1`` (pendubot) or
``tl2`` (acrobot) as the input's limits ``tau_min = -tl``, ``tau_max = tl``::

    from equilibrist import get_system
    from equilibrist.systems.dfki_parameters import read_model_parameters

    settings = read_model_parameters("model_parameters.yml", robot="pendubot")
    rig = get_system("dfki_double_pendulum", **settings)

The passive joint's limit is not a parameter (its motor is off). Ranges are checked when the
values are bound, as any setting's.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from equilibrist.errors import ParameterError, quote_outside

#: The model parameters a file may hold, by the file's (and the systems') names.
NAMES = ("m1", "m2", "l1", "l2", "r1", "r2", "I1", "I2", "Ir", "gr", "b1", "b2", "cf1", "cf2",
         "g")
#: The torque limits a file holds, per joint.
LIMITS = ("tl1", "tl2")
#: The robots: the joint each actuates (its limit's name).
ROBOTS = {"acrobot": "tl2", "pendubot": "tl1"}

_LINE = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*:\s*(.*?)\s*$")


def parse_model_parameters(text: str, *, where: str = "the file") -> dict[str, float]:
    """The ``name: number`` pairs of a flat YAML mapping *text* (comments and blank lines
    skipped); a line of any other shape, a repeated or unknown name, or a value that is not
    a finite number is refused in one line naming it."""
    values: dict[str, float] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip() or line.strip() == "---":
            continue
        match = _LINE.match(line)
        at = f"{where}, line {number}"
        if match is None:
            raise ParameterError(f"{at}: {quote_outside(raw.strip(), limit=60)} is not "
                                 "'name: number': expected a flat mapping of parameters")
        name, value = match.groups()
        if name not in NAMES and name not in LIMITS:
            raise ParameterError(f"{at}: unknown parameter {quote_outside(name, limit=40)}: "
                                 f"expected one of {', '.join(NAMES + LIMITS)}")
        if name in values:
            raise ParameterError(f"{at}: {name} is given twice")
        try:
            parsed = float(value.strip("'\""))
        except ValueError:
            parsed = math.nan
        if not math.isfinite(parsed):
            raise ParameterError(f"{at}: {name} = {quote_outside(value, limit=40)} is not a "
                                 "finite number")
        values[name] = parsed
    return values


def read_model_parameters(path: str | Path, *, robot: str) -> dict[str, float | str]:
    """The settings of ``dfki_double_pendulum`` as *robot* in the identified parameter file *path*.

    Parameters
    ----------
    path : str or Path
        A ``model_parameters.yml`` of the rig (its identification's output).
    robot : {"acrobot", "pendubot"}
        Which joint is actuated: its torque limit becomes ``tau_min``/``tau_max``.

    Returns
    -------
    dict
        ``{"robot": robot, name: value...}`` for :func:`equilibrist.get_system` (names the
        file does not hold keep the catalogue's defaults).

    Raises
    ------
    ParameterError
        A missing or unreadable file, a line that is not ``name: number``, an unknown or
        repeated name, a value that is not finite, a torque limit that is not positive.
    """
    if robot not in ROBOTS:
        raise ParameterError(f"robot {quote_outside(robot, limit=40)}: expected one of "
                             f"{', '.join(ROBOTS)}")
    p = Path(path)
    shown = quote_outside(str(p), limit=120)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ParameterError(f"no parameter file {shown}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{shown} cannot be read ({type(exc).__name__}): expected a "
                             "model_parameters.yml") from None
    values = parse_model_parameters(text, where=shown)
    settings: dict[str, float | str] = {"robot": robot}
    settings.update((k, v) for k, v in values.items() if k in NAMES)
    limit = values.get(ROBOTS[robot])
    if limit is not None:
        if not limit > 0:
            raise ParameterError(f"{shown}: {ROBOTS[robot]} = {limit:g} is the {robot}'s torque "
                                 "limit: expected a positive number")
        settings["tau_min"], settings["tau_max"] = -limit, limit
    return settings


def settings_of(model_parameters: object, *, robot: str) -> dict[str, float | str]:
    """The settings of ``dfki_double_pendulum`` as *robot* from the rig's own parameter object
    (``double_pendulum.model.model_parameters.model_parameters``: its lists ``m``, ``l``,
    ``r``, ``I``, ``b``, ``cf``, ``tl`` per joint, and ``Ir``, ``gr``, ``g``), as RealAIGym's
    leaderboard scripts hold it (``mpar``).

    Raises
    ------
    ParameterError
        An attribute missing or not a number, a torque limit of the actuated joint that is
        not positive.
    """
    if robot not in ROBOTS:
        raise ParameterError(f"robot {quote_outside(robot, limit=40)}: expected one of "
                             f"{', '.join(ROBOTS)}")
    values: dict[str, float] = {}
    try:
        for name in ("m", "l", "r", "I", "b", "cf", "tl"):
            pair = getattr(model_parameters, name)
            values[f"{name}1"], values[f"{name}2"] = float(pair[0]), float(pair[1])
        for name in ("Ir", "gr", "g"):
            values[name] = float(getattr(model_parameters, name))
    except (AttributeError, TypeError, ValueError, IndexError) as exc:
        raise ParameterError(f"the rig's parameters: {quote_outside(exc, limit=120)}: expected "
                             "the lists m, l, r, I, b, cf, tl and the numbers Ir, gr, g") from None
    limit = values[ROBOTS[robot]]
    if not limit > 0:
        raise ParameterError(f"{ROBOTS[robot]} = {limit:g} is the {robot}'s torque limit: "
                             "expected a positive number")
    settings: dict[str, float | str] = {"robot": robot}
    settings.update((k, v) for k, v in values.items() if k in NAMES)
    settings["tau_min"], settings["tau_max"] = -limit, limit
    return settings


__all__ = ["NAMES", "ROBOTS", "parse_model_parameters", "read_model_parameters", "settings_of"]

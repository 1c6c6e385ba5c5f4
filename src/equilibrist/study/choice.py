"""A study's controller: ``KIND``, or ``KIND:VALUE`` with the value of the kind's first option.

``--vary controller=lqr,policy:ppo.zip`` compares a trained network with the
model-based controllers in one study. ``KIND:VALUE`` is the kind *KIND* with
*VALUE* given to the first of its own options, as its record lists them
(:attr:`~equilibrist.controllers.kinds.ControllerKind.options`): the policy's
``--policy FILE``, the time-varying LQR's ``--trajectory FILE.npz``, the
MPC's ``--horizon N``, the swing-up's ``--balance``. So two networks, two
plans or two horizons are two values of one axis; the study's
``controller_options`` still give the kinds' other options. A file is
recorded as an absolute path (a cluster's workers read it) and named in the
table and the pictures by its file name (``policy:ppo.zip``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import quote_outside
from equilibrist.study.record import _does_not_apply, controllers

if TYPE_CHECKING:
    from equilibrist.controllers.kinds import Option
    from equilibrist.numeric.system import System


def is_file(option: Option) -> bool:
    """Whether *option* names a file (its metavar says ``FILE``)."""
    return "FILE" in str(option.metavar or "")


def _first(kind: str) -> Option | None:
    from equilibrist.controllers import kinds

    own = kinds.get(kind).options
    return own[0] if own else None


@dataclass(frozen=True)
class Choice:
    """A controller of a study: its *kind*, and the text of the kind's first option
    (*value*; None: the kind as the study's ``controller_options`` give it)."""

    kind: str
    value: str | None = None

    @property
    def text(self) -> str:
        """The recorded form: ``KIND`` or ``KIND:VALUE``."""
        return self.kind if self.value is None else f"{self.kind}:{self.value}"

    @property
    def label(self) -> str:
        """How the table and the pictures name it: a file by its file name."""
        if self.value is None:
            return self.kind
        first = _first(self.kind)
        shown = Path(self.value).name if first is not None and is_file(first) else self.value
        return f"{self.kind}:{shown}"

    def options(self, study_options: dict[str, str] | None = None) -> dict[str, str]:
        """The kind's options as text: the study's, with the value's own in front."""
        out = dict(study_options or {})
        first = _first(self.kind)
        if self.value is not None and first is not None:
            out[first.key] = self.value
        return out


def parse_choice(text: str) -> Choice:
    """The choice a recorded study names (checked when the study was made)."""
    kind, sep, value = str(text).partition(":")
    return Choice(kind.strip().lower(), value.strip() if sep else None)


def check_choice(system: System, value: object, what: str, problems: list[str]) -> Choice | None:
    """*value* (``KIND`` or ``KIND:VALUE``) as a :class:`Choice` of *system*, a file resolved
    to an absolute path; or None after naming every problem in *problems* (*what* is the
    option, ``--vary controller`` or ``--controller``)."""
    text = str(value).strip()
    choice = parse_choice(text)
    known = controllers()
    if choice.kind not in known:
        problems.append(f"{what}: '{quote_outside(text)}' is not a controller (expected one of "
                        f"{', '.join(known)}, or KIND:VALUE such as policy:FILE)")
        return None
    why = _does_not_apply(choice.kind, system)
    if why is not None:
        problems.append(f"{what}: {why}")
        return None
    if choice.value is None:
        return choice
    first = _first(choice.kind)
    if first is None:
        problems.append(f"{what}: '{quote_outside(text)}': the {choice.kind} controller takes no "
                        "option to give a value to (KIND:VALUE gives VALUE to the kind's first "
                        "option)")
        return None
    if not choice.value:
        problems.append(f"{what}: '{quote_outside(text)}': expected {choice.kind}:"
                        f"{first.metavar or 'VALUE'} (its {first.flag})")
        return None
    from equilibrist.controllers.kinds import KindError

    try:
        first.value(choice.value)
    except KindError as exc:
        problems.append(f"{what}: '{quote_outside(text)}': {exc}")
        return None
    if not is_file(first):
        return choice
    path = Path(choice.value).expanduser().resolve()
    if not path.is_file():
        problems.append(f"{what}: '{quote_outside(text)}': no such file '{quote_outside(str(path))}' "
                        f"(expected {choice.kind}:{first.metavar})")
        return None
    return Choice(choice.kind, str(path))


def check_builds(system: System, choice: Choice, *, rate: float, options: dict[str, str],
                 what: str, problems: list[str]) -> None:
    """Build the controller of a *choice* whose value is a file (``policy:FILE``) once, at
    *system* (the study's nominal plant), so a file that is not what its kind reads (a
    network, a plan) is refused before the study runs, not found by every point. (A file
    of the study's ``controller_options`` is checked to exist only: building a tracked
    plan's filter takes seconds.)"""
    from equilibrist.controllers import kinds
    from equilibrist.errors import EquilibristError
    from equilibrist.study.record import kind_options

    first = _first(choice.kind)
    if choice.value is None or first is None or not is_file(first):
        return
    try:
        parsed = kind_options(choice.kind, choice.options(options))
        request = kinds.ControllerRequest(system=system, rate=rate, options=parsed)
        kinds.get(choice.kind).make(request)
    except EquilibristError as exc:
        problems.append(f"{what}: {choice.label}: {exc}")


__all__ = ["Choice", "check_builds", "check_choice", "is_file", "parse_choice"]

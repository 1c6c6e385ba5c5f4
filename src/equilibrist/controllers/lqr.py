"""``--controller lqr``: the discrete LQR on the full state (every state measured)."""

from __future__ import annotations

import re

from equilibrist.controllers.kinds import ControllerKind, Option, linear_builder


def _delay_text(text: str) -> str:
    """``N`` or ``Ts``/``Tms`` (read as periods at the run's rate when the design is made)."""
    word = text.strip()
    if not re.fullmatch(r"\d+|(\d+\.?\d*|\.\d+)(e[-+]?\d+)?m?s", word):
        raise ValueError(word)
    return word


#: ``--design-delay``: the loop delay the LQR and the LQG designs compensate (one option,
#: both kinds' records; :func:`equilibrist.control.design_extended.delay_periods` reads it).
DESIGN_DELAY = Option(
    "--design-delay",
    "the loop's delay the design compensates: N control periods, or seconds (4ms, 0.004s); "
    "designed on the plant extended by the commands in flight (default 0: none)",
    parse=_delay_text, metavar="N|Ts",
    expected="a whole number of control periods >= 0, or seconds (4ms, 0.004s)",
)

KIND = ControllerKind(
    name="lqr", label="LQR (true state)", help="LQR on the full state (every state measured)",
    build=linear_builder("lqr"), options=(DESIGN_DELAY,),
    noise="design", linear=True, loop="lqr", order=10,
)

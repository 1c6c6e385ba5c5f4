"""Numbers as a person writes them on a command line or in a form: plain decimals.

Python's ``float()`` and ``int()`` take more than is ever meant there (``1_0`` is ten, digits
of other scripts, ``inf``); every place that reads a number a user typed checks it here first.
"""

from __future__ import annotations

import re

# Digits with a point and an exponent: -0.5, 2, 1e-3.
DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
# What float() reads as not finite; a reader says so in its own words.
NOT_FINITE = re.compile(r"[+-]?(?:inf|infinity|nan)", re.IGNORECASE)
# Decimal digits only: a whole number.
WHOLE = re.compile(r"[+-]?[0-9]+")


def is_decimal(text: str) -> bool:
    """Whether *text* (blanks around it ignored) is a plain decimal number."""
    return DECIMAL.fullmatch(text.strip()) is not None


def is_whole(text: str) -> bool:
    """Whether *text* (blanks around it ignored) is a whole number in decimal digits."""
    return WHOLE.fullmatch(text.strip()) is not None

"""Helpers shared by test modules (no tests here): test modules import these, never each other."""

from __future__ import annotations

import shutil

import pytest


def require(*names: str) -> str:
    """The path of the first of the programs *names* found, else a failure naming them.

    A test that needs a tool (``make``, a C or C++ compiler) fails where the
    tool is missing: a skipped test proves nothing, and CI has them.
    """
    for name in names:
        path = shutil.which(name)
        if path is not None:
            return path
    pytest.fail(f"this test needs {' or '.join(names)} on PATH (install it; CI has it)",
                pytrace=False)

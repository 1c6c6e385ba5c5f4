"""Importing a module as if one of its optional dependencies were not installed."""

from __future__ import annotations

import importlib
import importlib.util
import sys

import pytest


def import_without(monkeypatch: pytest.MonkeyPatch, dependency: str, module: str) -> None:
    """Import *module* afresh with ``importlib.util.find_spec(dependency)`` answering None
    (what a module that checks for its optional dependency sees where it is missing)."""
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == dependency else real(name, *a))
    monkeypatch.delitem(sys.modules, module)
    importlib.import_module(module)

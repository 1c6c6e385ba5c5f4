"""Plug-ins that misbehave: each is one line naming it, exit status 2, its text escaped, and
nothing of it in a command's own output.

Each plug-in is a module in a temporary folder found through its entry point
(tests/support/plugins.py), as a package installed by pip is: a controller kind whose
``build`` or ``applies`` raises, a module that prints when imported, one that calls
``sys.exit(0)`` when imported, one that raises with a text that would retitle and clear
the terminal.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from tests.support.plugins import cli, install

KINDS = "equilibrist.controllers"
SYSTEMS = "equilibrist.systems"
# A text that would set the terminal's title, ring, clear the screen and turn the line around.
HOSTILE = r"\x1b]0;PWNED\x07\x1b[2J\r\u202eevil"
SHOWN = "\\x1b]0;PWNED\\x07\\x1b[2J\\r\\u202eevil"  # how it must be printed
RAW = ("\x1b", "\x07", "\r", "\u202e")


def failing_kind(name: str, what: str) -> str:
    """A kind's module whose *what* (``build`` or ``applies``) raises with the hostile text."""
    other = "" if what == "build" else ', build=linear_builder("lqr")'
    return f'''
from equilibrist.controllers.kinds import ControllerKind, linear_builder


def fails(_):
    raise RuntimeError("{HOSTILE}")


KIND = ControllerKind(name="{name}", label="fails", help="a kind whose {what} raises",
                      {what}=fails{other})
'''


PRINTING_KIND = '''
print("noise printed at import\\x1b]0;PWNED\\x07\\x1b[2J")

from equilibrist.controllers.kinds import ControllerKind, linear_builder

KIND = ControllerKind(name="chatty", label="chatty", help="the LQR, printed at import",
                      build=linear_builder("lqr"))
'''

QUITTING = '''
print("printed before quitting")
import sys

sys.exit(0)
'''


def _one_line(done: object, *words: str) -> str:
    err: str = done.stderr  # type: ignore[attr-defined]
    assert done.returncode == 2, err  # type: ignore[attr-defined]
    assert not any(c in err for c in RAW), repr(err)
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("equilibrist: error: "), err
    for word in words:
        assert word in last, err
    return last


@pytest.fixture(scope="module")
def failing(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    folder = tmp_path_factory.mktemp("failing")
    install(folder, "fails_build", failing_kind("failsbuild", "build"), KINDS, "failsbuild",
            "fails_build:KIND")
    return install(folder, "fails_applies", failing_kind("failsapplies", "applies"), KINDS,
                   "failsapplies", "fails_applies:KIND")


@pytest.mark.parametrize("command", [
    ("simulate", "cartpole", "--duration", "0.5", "--json"),
    ("design", "cartpole", "--json"),
    ("export", "cartpole", "--duration", "0.5"),
    ("batch", "cartpole", "--runs", "2", "--duration", "0.5", "--json"),
])
def test_a_kind_whose_build_raises_is_one_line_in_every_command(
        failing: dict[str, str], command: tuple[str, ...], tmp_path: Path) -> None:
    out = tmp_path / "out"
    extra = ("--out", str(out)) if command[0] == "export" else ()
    done = cli(failing, *command, "--controller", "failsbuild", *extra)
    _one_line(done, "'failsbuild' (fails_build:KIND)", "build", "RuntimeError", SHOWN)
    assert done.stdout == "" and not out.exists()


def test_a_kind_whose_applies_raises_is_one_line(failing: dict[str, str]) -> None:
    done = cli(failing, "simulate", "cartpole", "--controller", "failsapplies", "--json")
    _one_line(done, "'failsapplies' (fails_applies:KIND)", "applies", "RuntimeError", SHOWN)
    assert done.stdout == ""


def test_what_a_kind_prints_at_import_stays_out_of_the_json(tmp_path: Path) -> None:
    env = install(tmp_path, "chatty_kind", PRINTING_KIND, KINDS, "chatty", "chatty_kind:KIND")
    done = cli(env, "simulate", "cartpole", "--duration", "0.5", "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["system"] == "cartpole"  # nothing but the JSON
    assert "printed at import" in done.stderr
    # ... and escaped there: no escape sequence reaches the terminal from a plug-in's print.
    assert not any(c in done.stderr for c in RAW), repr(done.stderr)
    assert "\\x1b]0;PWNED\\x07" in done.stderr
    # And the kind itself is there and runs.
    assert cli(env, "simulate", "cartpole", "--duration", "0.5", "--controller", "chatty",
               "--json").returncode == 0


@pytest.mark.parametrize("group", [KINDS, SYSTEMS])
def test_a_module_that_exits_at_import_is_a_load_failure_not_the_command_s_exit(
        group: str, tmp_path: Path) -> None:
    env = install(tmp_path, "quitter", QUITTING, group, "quitter")
    done = cli(env, "simulate", "cartpole", "--duration", "0.5", "--json")
    _one_line(done, "'quitter'", "cannot be loaded: SystemExit: 0")
    assert done.stdout == ""
    assert "printed before quitting" in done.stderr


@pytest.mark.parametrize("group", [KINDS, SYSTEMS])
def test_a_module_that_raises_at_import_is_named_with_its_text_escaped(
        group: str, tmp_path: Path) -> None:
    env = install(tmp_path, "raiser", f'raise ValueError("{HOSTILE}")\n', group, "raiser")
    done = cli(env, "simulate", "cartpole", "--duration", "0.5", "--json")
    _one_line(done, "'raiser'", "cannot be loaded: ValueError: " + SHOWN)
    assert done.stdout == ""

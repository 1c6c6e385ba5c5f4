"""What a newcomer reads and pastes: numbers printed as they are meant, numbers read as
written, advice that names the command's own options, progress on a long command, and the
README's commands that run as pasted."""

from __future__ import annotations

import json
import math
import re

import pytest

from equilibrist.cli.main import main

# A zero printed with a sign: "-0" standing alone (not -0.5, not 1e-05).
SIGNED_ZERO = re.compile(r"(?<![\w.])-0(?:\.0*)?(?![\w.])")


def _one_line(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, err


# -- signed zeros -----------------------------------------------------------------------

@pytest.mark.parametrize("system", ["cartpole", "acrobot"])
def test_show_prints_zeros_without_a_sign(capsys, system) -> None:
    assert main(["show", system]) == 0
    out = capsys.readouterr().out
    text = out[out.index("linearization at"):]
    assert not SIGNED_ZERO.search(text), text


def test_the_cartpole_without_friction_has_two_zero_poles_printed_as_0(capsys) -> None:
    # b_c = b_p = 0: the cart's position and speed are free, two poles at the origin;
    # its A has a zero where the friction would be (x_dot row, x_dot column).
    assert main(["linearize", "cartpole"]) == 0
    out = capsys.readouterr().out
    poles = next(line for line in out.splitlines() if line.startswith("open-loop poles:"))
    assert poles.split(":", 1)[1].split(", ").count("0") == 2, poles
    row = next(line for line in out.splitlines() if line.split()[:1] == ["x_dot"]
               and len(line.split()) == 5)
    assert row.split()[3] == "0", row


def _negative_zeros(obj: object, where: str = "") -> list[str]:
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _negative_zeros(v, f"{where}.{k}")]
    if isinstance(obj, list):
        return [p for k, v in enumerate(obj) for p in _negative_zeros(v, f"{where}[{k}]")]
    if isinstance(obj, float) and obj == 0.0 and math.copysign(1.0, obj) < 0:
        return [where]
    return []


@pytest.mark.parametrize("system", ["cartpole", "acrobot"])
def test_linearize_json_has_no_negative_zero_where_the_text_prints_0(capsys, system) -> None:
    assert main(["linearize", system, "--json"]) == 0
    raw = capsys.readouterr().out
    assert _negative_zeros(json.loads(raw)) == []
    assert "-0.0," not in raw and "-0.0\n" not in raw


# -- numbers as written ------------------------------------------------------------------

@pytest.mark.parametrize(("argv", "words"), [
    (["linearize", "cartpole", "--at", "theta=1_0"], ["--at theta", "'1_0'", "not a number"]),
    (["design", "cartpole", "--at", "theta=0_1"], ["--at theta", "'0_1'"]),
    (["linearize", "cartpole", "--input", "F=1_0"], ["--input F", "'1_0'"]),
    (["linearize", "cartpole", "--set", "m_p=1_0"], ["--set m_p", "'1_0'"]),
    (["design", "cartpole", "--q", "1_0,1,1,1"], ["--q", "'1_0'"]),
    (["linearize", "cartpole", "--at", "theta=\u0661"], ["--at theta", "not a number"]),
    (["roa", "cartpole", "--samples", "1_000"], ["--samples", "'1_000'", "whole number"]),
    (["roa", "cartpole", "--seed", "1_0"], ["--seed", "'1_0'", "whole number"]),
])
def test_a_number_with_an_underscore_is_refused_in_one_line(capsys, argv, words) -> None:
    code = main(argv)
    _one_line(code, capsys.readouterr().err, *words)


@pytest.mark.parametrize("value", ["0.1", ".1", "+0.1", "1e-1", "1E-1", " 0.1"])
def test_ordinary_decimals_are_read(capsys, value) -> None:
    assert main(["linearize", "cartpole", "--at", f"theta={value}", "--json"]) == 0
    x0 = json.loads(capsys.readouterr().out)["x0"]
    assert x0[1] == 0.1

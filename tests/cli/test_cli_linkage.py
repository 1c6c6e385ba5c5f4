"""The linkage command: exact solution, rate ratio, and its one-line errors."""

from __future__ import annotations

import json
import math

import pytest

from equilibrist.cli.main import main

GEOMETRY = "a=0.05,b=0.03,c=0.06,d=0.04,e=0.06"


def test_platform_angle_closes_the_loop(capsys) -> None:
    assert main(["linkage", "--geometry", GEOMETRY, "--motor-angle", "0.3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    a, b, c, d, e = 0.05, 0.03, 0.06, 0.04, 0.06
    theta, phi = out["theta"], out["phi"]
    # The loop closure of SYSTEMS.md, written out here independently.
    closure = (d * math.cos(theta) - c * math.cos(phi) - a) ** 2 + (
        d * math.sin(theta) - c * math.sin(phi) - b) ** 2 - e**2
    assert abs(closure) < 1e-12
    assert out["branch"] == "plus"


def test_parallelogram_moves_one_to_one(capsys) -> None:
    # The seed's special case c = d, a = b, e = sqrt(2) b: theta = phi.
    geometry = f"a=0.04,b=0.04,c=0.04,d=0.04,e={math.sqrt(2) * 0.04!r}"
    assert main(["linkage", "--geometry", geometry, "--platform-angle", "0.2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["theta"] == pytest.approx(0.2, abs=1e-12)
    assert out["rate_ratio"] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--geometry", "a=0.04,b=0.04,c=0.04,d=0.04,e=0.5", "--platform-angle", "0.1"], "cannot be assembled"),
        (["--geometry", "a=0.04,b=0.04,c=0.04", "--platform-angle", "0.1"], "missing d, e"),
        (["--geometry", GEOMETRY + ",f=1", "--platform-angle", "0.1"], "unknown length(s) f"),
        (["--geometry", "a=0.04,b=0.04,c=-1,d=0.04,e=0.05", "--platform-angle", "0.1"], "c = -1 is out of range"),
        (["--geometry", GEOMETRY, "--platform-angle", "nan"], "not a finite number"),
    ],
)
def test_bad_input_is_one_line(capsys, argv, needle) -> None:
    assert main(["linkage", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]

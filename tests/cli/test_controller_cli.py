"""``--controller`` and ``--at`` on simulate, batch, design and export."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from equilibrist.cli.main import main


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def _refused(capsys, argv, *words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for w in words:
        assert w in err, err
    return err


def test_design_at_the_hanging_point(capsys):
    out = _json(capsys, ["design", "cartpole", "--rate", "100", "--at", f"theta={math.pi}",
                         "--json"])
    assert out["x0"][1] == pytest.approx(math.pi)
    # Hanging, the open loop is stable already: every open-loop pole has |z| <= 1.
    A = np.array(out["discrete"]["A"])
    assert np.all(np.abs(np.linalg.eigvals(A)) <= 1 + 1e-9)
    form = out["controller"]
    assert form["kind"] == "lqg" and form["form"] == "current"
    assert np.array(form["Ac"]).shape == (4, 4)
    lqr = _json(capsys, ["design", "cartpole", "--rate", "100", "--controller", "lqr", "--json"])
    assert np.array(lqr["controller"]["Dy"]) == pytest.approx(-np.array(lqr["K"]))


def test_simulate_and_batch_at_the_hanging_point(capsys):
    argv = ["--at", f"theta={math.pi}", "--duration", "3", "--noise", "off"]
    run = _json(capsys, ["simulate", "cartpole", "--controller", "lqr", "--x0", "theta=2.9",
                         *argv, "--json"])
    assert run["fell"] is False
    assert abs(run["final_error"]["theta"]) < 0.05  # back at the hanging point
    batch = _json(capsys, ["batch", "cartpole", "--controller", "lqg", "--runs", "6",
                           "--x0", "theta=2.8:3.4", *argv, "--json"])
    assert batch["runs"] == 6 and batch["stayed_up"] == 6


def test_controllers_that_do_not_apply_are_one_line(capsys, tmp_path):
    _refused(capsys, ["simulate", "ball_beam", "--controller", "swingup", "--duration", "1"],
             "swing")
    _refused(capsys, ["batch", "ball_beam", "--controller", "swingup", "--runs", "2",
                      "--duration", "1"], "swing")
    _refused(capsys, ["design", "cartpole", "--controller", "none"], "nothing to design")
    _refused(capsys, ["export", "cartpole", "--controller", "none", "--out",
                      str(tmp_path / "x")], "no controller to export")
    _refused(capsys, ["design", "cartpole", "--at", "theta=1.0"], "no equilibrium", "theta")
    _refused(capsys, ["design", "cartpole", "--at", "phi=1.0"], "phi")
    _refused(capsys, ["simulate", "cartpole", "--controller", "pid"], "pid")
    assert not (tmp_path / "x").exists()

"""``equilibrist design --design-delay``: the design shown is the one the kind builds."""

from __future__ import annotations

import json

import numpy as np

from equilibrist.cli.main import main


def test_design_shows_the_delayed_design_and_its_controller(capsys) -> None:
    argv = ["design", "cartpole", "--rate", "50", "--controller", "lqr", "--json"]
    assert main(argv) == 0
    plain = json.loads(capsys.readouterr().out)
    assert main([*argv, "--design-delay", "40ms"]) == 0
    late = json.loads(capsys.readouterr().out)
    assert plain["delay"] == 0 and late["delay"] == 2
    assert late["model_states"] == [*plain["states"], "F_sent2", "F_sent1"]
    assert np.shape(late["K"]) == (1, 6) and np.shape(plain["K"]) == (1, 4)
    # The controller holds the two commands in flight: its record shifts them along.
    assert late["controller"]["Ac"] == [[0.0, 1.0], [0.0, 0.0]]
    assert late["controller"]["Bu"] == [[0.0], [1.0]]
    assert main(["design", "cartpole", "--controller", "lqr", "--design-delay", "2"]) == 2
    assert "--design-delay needs --rate" in capsys.readouterr().err

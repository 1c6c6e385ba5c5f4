"""``equilibrist robustness --policy FILE``: a trained network's scorecard.

The truth: a network of one layer that is the LQR (tests/support/networks.py) has the LQR's
scorecard, run for run; the summary names the kind that ran (--policy alone: the network)."""

from __future__ import annotations

import json

from equilibrist.cli.main import main
from support.networks import cartpole_lqr_network

RATE = 50.0  # slow enough that the motor's lag loses some runs: a card that can differ


def test_a_network_that_is_the_lqr_has_the_lqrs_scorecard(tmp_path, capsys) -> None:
    net = tmp_path / "lqr.pt"
    cartpole_lqr_network(net, rate=RATE)
    common = ["--families", "torque_response", "--duration", "2", "--rate", f"{RATE:g}",
              "--x0", "theta=0.3"]
    cards = []
    for kind in (["--controller", "lqr"], ["--policy", str(net)]):
        assert main(["robustness", "cartpole", *kind, *common, "--json"]) == 0
        cards.append(json.loads(capsys.readouterr().out))
    lqr, policy = cards
    assert policy["families"] == lqr["families"]
    assert 0.0 < lqr["scores"]["torque_response"] < 1.0
    assert (lqr["controller"], policy["controller"]) == ("lqr", "policy")

"""``--controller lqr`` and ``lqg`` with ``--design-delay``: a run through a rig whose loop is
two periods late balances with the design delay and falls without it."""

from __future__ import annotations

import json

import pytest

from equilibrist.cli.main import main

#: The double cart-pole at 100 Hz: two periods late, its undelayed LQR's loop is unstable.
RUN = ["simulate", "double_cartpole", "--rate", "100", "--duration", "6", "--x0",
       "theta1=0.05", "--json"]


def _fell(capsys, argv: list[str]) -> bool:
    assert main(argv) == 0
    return bool(json.loads(capsys.readouterr().out)["fell"])


@pytest.mark.parametrize(("kind", "rig"), [("lqr", "--actuation-delay"),
                                           ("lqg", "--measurement-delay")])
def test_a_run_two_periods_late_balances_only_with_the_design_delay(capsys, kind, rig) -> None:
    late = [*RUN, "--controller", kind, rig, "2"]
    assert _fell(capsys, late)
    assert not _fell(capsys, [*late, "--design-delay", "2"])
    assert not _fell(capsys, [*late, "--design-delay", "20ms"])  # the same, in seconds


def test_bad_design_delays_are_one_line(capsys) -> None:
    for value, words in (("x", "--design-delay 'x': expected a whole number"),
                         ("5ms", "design delay 5ms is 0.5 control periods at 100 Hz")):
        assert main([*RUN, "--controller", "lqr", "--design-delay", value]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1
    assert main([*RUN, "--controller", "none", "--design-delay", "2"]) == 2
    assert "--design-delay is an option of --controller lqr or --controller lqg" in \
        capsys.readouterr().err


def test_roa_of_a_delayed_lqr_says_why_it_has_no_certificate(capsys) -> None:
    """Its Riccati function is on the commands in flight too, not on the plant's starts."""
    assert main(["roa", "double_cartpole", "--controller", "lqr", "--rate", "100",
                 "--design-delay", "2", "--samples", "100", "--duration", "0.2",
                 "--boxes", "1000", "--falsify", "0", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["rho"] is None and figures["certified"] is False
    assert "designed for a delay" in figures["certificate_note"]

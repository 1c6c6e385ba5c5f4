"""``--controller lqg --design-delay``: the controller for a delayed loop is a linear controller
like any other, so the export writes it and ``make check`` replays its vectors exactly."""

from __future__ import annotations

import json
import re

from equilibrist.cli.main import main
from support.export import make_check


def test_an_lqg_designed_for_two_periods_exports_and_checks_exactly(tmp_path, capsys) -> None:
    out = tmp_path / "late"
    assert main(["export", "double_cartpole", "--controller", "lqg", "--rate", "100",
                 "--design-delay", "2", "--out", str(out)]) == 0
    capsys.readouterr()
    printed = make_check(out)
    count = re.search(r"(\d+) samples, (\d+) mismatches", printed)
    assert count is not None, printed
    assert int(count.group(1)) > 100 and int(count.group(2)) == 0
    # The C holds the controller's state: the filter's prediction of the plant's six states
    # and of the two commands in flight.
    assert re.search(r"#define LQG_NZ 8\b", (out / "lqg.h").read_text())


#: The DFKI acrobot measuring its rates too, through a rig that low-passes them at 2 Hz.
FILTERED = ["simulate", "dfki_double_pendulum", "--controller", "lqg", "--outputs",
            "theta1,theta2,theta1_dot,theta2_dot", "--rn", "1e-12,1e-12,1e-9,1e-9", "--set",
            "Ir=0", "b1=0", "b2=0", "cf1=0", "cf2=0", "--x0", "theta1=3.1", "--rate", "500",
            "--duration", "3", "--velocity-filter", "2", "--json"]


def test_an_lqg_designed_for_the_rigs_velocity_filter_balances_where_it_falls_without(
        capsys) -> None:
    """The Kalman filter that takes the lagging rates for the rates themselves loses the
    rig; the one whose model includes the rig's filter (--design-velocity-filter) holds it."""
    assert main(FILTERED) == 0
    assert json.loads(capsys.readouterr().out)["fell"]
    assert main([*FILTERED, "--design-velocity-filter", "2"]) == 0
    assert not json.loads(capsys.readouterr().out)["fell"]
    assert main([*FILTERED, "--design-velocity-filter", "0"]) == 2
    assert "--design-velocity-filter '0': expected a cutoff in Hz > 0" in capsys.readouterr().err
    assert main([*FILTERED[:4], "--design-velocity-filter", "2", "--duration", "1"]) == 2
    err = capsys.readouterr().err
    assert "is a joint's rate" in err and err.count("\n") == 1

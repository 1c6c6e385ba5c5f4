"""``--controller lqg --design-delay``: the controller for a delayed loop is a linear controller
like any other, so the export writes it and ``make check`` replays its vectors exactly."""

from __future__ import annotations

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

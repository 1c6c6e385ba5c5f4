"""``equilibrist pil``: the figures scripts read, the saved run, and the one-line refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.pil.targets import get
from equilibrist.sim import SimResult
from support import require

#: The keys scripts outside the project read.
KEYS = {"target", "clock_hz", "cycles_per_step", "cycles_exact", "budget_cycles",
        "budget_fraction", "flash_bytes", "ram_bytes", "stack_bytes", "max_rate", "steps",
        "max_deviation", "fits"}


def _tools(target: str) -> None:
    for tool, _ in get(target).tools:
        require(tool)


@pytest.mark.slow
def test_the_json_has_the_figures_and_the_run_is_saved(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    _tools("uno")
    out = tmp_path / "run.npz"
    assert main(["pil", "cartpole", "--controller", "lqg", "--target", "uno", "--duration",
                 "0.05", "--x0", "theta=0.1", "--json", "--out", str(out)]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert set(figures) >= KEYS
    assert figures["target"] == "uno" and figures["clock_hz"] == 16_000_000
    assert figures["budget_cycles"] == 80_000 and figures["cycles_exact"] is True
    worst = figures["cycles_per_step"]["max"]
    assert figures["cycles_per_step"]["median"] <= worst
    assert figures["budget_fraction"] == pytest.approx(worst / 80_000)
    assert figures["max_rate"] == 16_000_000 // worst
    assert figures["steps"] == 11 and figures["fits"] is True and figures["fault"] is None
    assert figures["report"] == (f"LQG at 200 Hz: {worst:,} cycles of 80,000, "
                                 f"{100 * worst / 80_000:.1f} %")
    run = SimResult.load(out)
    assert run.n_rows == 11 and run.settings["pil"]["cycles_per_step"]["max"] == worst
    assert np.all(np.isfinite(run.commanded))


@pytest.mark.slow
def test_a_step_over_its_period_is_a_fault(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """An LQG on the Uno at 1 kHz: about 19,000 cycles a step against 16,000 a period."""
    _tools("uno")
    out = tmp_path / "run.npz"
    assert main(["pil", "cartpole", "--controller", "lqg", "--target", "uno", "--rate", "1000",
                 "--duration", "0.01", "--json", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    figures = json.loads(captured.out)
    assert figures["budget_cycles"] == 16_000 and figures["fits"] is False
    assert figures["cycles_per_step"]["max"] > 16_000 and figures["budget_fraction"] > 1
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "overran its period" in lines[0] and str(out) in lines[0]
    assert out.exists()


@pytest.mark.parametrize(("argv", "said"), [
    (["--target", "pdp11"], "--target"),
    (["--target", "uno", "--timeout", "0"], "--timeout 0"),
    (["--target", "uno", "--controller", "none"], "open loop"),
])
def test_bad_options_are_one_line(argv: list[str], said: str,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["pil", "cartpole", *argv]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and said in lines[0]

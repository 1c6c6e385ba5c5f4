"""Processor in the loop of the MPC: its firmware (DAQP with the generated driver) on the
Cortex-M4F equals ``simulate``; on the Uno it does not fit, said in one line with its figures.

One module, so that the Uno's refusal reads the sketch the Cortex-M4F's run exported (the
cache), on the same worker.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from pil_runs import figures_are_the_chips, pil, same_commands

from equilibrist.cli.main import main
from equilibrist.pil.targets import get
from support import require


@pytest.mark.slow
def test_the_mpc_runs_on_the_cortex_m4f_as_simulate() -> None:
    run = pil("mpc", "cortex-m4f")
    same_commands(run, 1e-9)  # double in the export, float64 on the link
    figures_are_the_chips(run, 168_000_000, 1_048_576, 131_072)
    assert run.fits


@pytest.mark.slow
def test_the_mpc_does_not_fit_the_uno_in_one_line(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """After the MPC's run on the Cortex-M4F: the same export's sketch, from the cache,
    refused by the Uno's compiler, said in one line with its figures."""
    for tool, _ in get("uno").tools:
        require(tool)
    out = tmp_path / "run.npz"
    assert main(["pil", "cartpole", "--controller", "mpc", "--target", "uno", "--duration",
                 "0.05", "--out", str(out)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "MPC does not fit the uno" in lines[0]
    assert "bytes of RAM" in lines[0] and "2,048" in lines[0]
    assert not out.exists()

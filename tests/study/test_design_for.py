"""``--design-for nominal`` with a parameter both set and varied: the set value is the
nominal the one design is made for, the varied values are the plants it runs. The truth is
each plant simulated alone under the LQR designed for the set value."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.numeric.lookup import get_system
from equilibrist.sim.run import simulate

RATE = 200.0
X0 = np.array([0.0, 0.15, 0.0, 0.0])


def _peak(plant_m_p: float, design_m_p: float) -> float:
    d = design(get_system("cartpole", m_p=design_m_p), rate=RATE)
    ctrl = LinearController.from_design(d, kind="lqr")
    run = simulate(get_system("cartpole", m_p=plant_m_p), ctrl, x0=X0, duration=1.0, rate=RATE)
    return float(np.abs(run.applied).max())


def test_a_set_parameter_is_the_nominal_of_a_varied_one(tmp_path, capsys) -> None:
    out = tmp_path / "s.parquet"
    assert main(["sweep", "cartpole", "--set", "m_p=0.3", "--vary", "m_p=0.1,0.3",
                 "--design-for", "nominal", "--controller", "lqr", "--noise", "off",
                 "--x0", "theta=0.15", "--runs", "1", "--duration", "1", "--out", str(out),
                 "--no-progress", "--json"]) == 0
    capsys.readouterr()
    rows = pq.read_table(out).to_pylist()
    assert [r["m_p"] for r in rows] == [0.1, 0.3]
    for row in rows:
        assert row["status"] == "ok"
        assert row["peak_input_max.F"] == pytest.approx(_peak(row["m_p"], 0.3), rel=1e-9)
    # The set value mattered: the catalogue's m_p (1) gives another design and other commands.
    assert rows[0]["peak_input_max.F"] != pytest.approx(_peak(0.1, 1.0), rel=1e-3)

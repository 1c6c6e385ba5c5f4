"""A study's controller ``KIND:VALUE``: a trained policy beside the model-based controllers.

The truth: a network of one ``Linear`` layer whose weights are the LQR's gain written in the
policy's units (observations in Bryson scales, actions in [-1, 1] of the force's limits) *is*
that LQR, so its row of the study must be the LQR's row; a network with twice the gain is
another controller, and its row differs. Bad files are one line, exit status 2, nothing
written.
"""

from __future__ import annotations

import json

import pyarrow.parquet as pq
import pytest
import torch

from equilibrist.cli.main import main
from equilibrist.study import load_study_file, make_study, read_study
from support.networks import cartpole_lqr_network

RATE = 200.0  # the cart-pole's control rate, the study's
METRICS = ("fraction_up", "settling_p50", "settling_max", "cost_mean", "peak_input_max.F")


def _lqr_as_network(path, gain: float = 1.0) -> None:
    cartpole_lqr_network(path, rate=RATE, gain=gain)


def test_a_policy_is_a_value_of_the_controller_axis_named_by_its_file(tmp_path, capsys):
    _lqr_as_network(tmp_path / "lqr_net.pt")
    _lqr_as_network(tmp_path / "double.pt", gain=2.0)
    toml = tmp_path / "study.toml"
    # One start (each point draws its own starts from a range): the points differ by their
    # controllers alone.
    toml.write_text('system = "cartpole"\nruns = 2\nduration = 1\n'
                    '[vary]\ncontroller = ["lqr", "policy:lqr_net.pt", "policy:double.pt"]\n'
                    'noise = [0]\n'
                    '[x0]\ntheta = 0.05\nx = "0.1"\n')
    out = tmp_path / "s.parquet"
    # From another folder: the study file's relative files are read from beside it.
    assert main(["sweep", "--study", str(toml), "--out", str(out), "--no-progress",
                 "--json"]) == 0
    recorded = json.loads(capsys.readouterr().out)["study"]["vary"][0]["values"]
    assert recorded == ["lqr", f"policy:{tmp_path / 'lqr_net.pt'}",
                        f"policy:{tmp_path / 'double.pt'}"]
    rows = pq.read_table(out).to_pylist()
    assert [r["controller"] for r in rows] == ["lqr", "policy:lqr_net.pt", "policy:double.pt"]
    assert [r["status"] for r in rows] == ["ok"] * 3
    lqr, net, double = rows
    for m in METRICS:  # the network is the LQR: the same runs, to round-off
        assert net[m] == pytest.approx(lqr[m], rel=1e-6, abs=1e-9), m
    assert double["cost_mean"] != pytest.approx(lqr["cost_mean"], rel=1e-3)
    # The pictures pick a policy by its file's name.
    png = tmp_path / "p.png"
    assert main(["plot", str(out), "--x", "noise", "--where", "controller=Policy:double.pt",
                 "--metric", "cost_mean", "--out", str(png)]) == 0
    capsys.readouterr()
    assert main(["plot", str(out), "--x", "noise", "--where", "controller=policy:x.pt",
                 "--out", str(png)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "values: lqr, policy:double.pt, policy:lqr_net.pt" in err
    _, study = read_study(out)
    assert study.point(2)["controller"] == f"policy:{tmp_path / 'double.pt'}"


def test_files_are_recorded_as_absolute_paths(tmp_path, monkeypatch, capsys):
    """A file relative to the working folder is recorded as an absolute path."""
    _lqr_as_network(tmp_path / "net.pt")
    monkeypatch.chdir(tmp_path)
    study = make_study("cartpole", vary={"controller": "lqr,policy:net.pt"}, runs=2)
    assert study.axes[0].values == ("lqr", f"policy:{tmp_path / 'net.pt'}")
    assert study.controller == "lqg"
    # A study file's controller, not varied, reads its file from beside the study file.
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "net.pt").write_bytes((tmp_path / "net.pt").read_bytes())
    toml = tmp_path / "sub" / "one.toml"
    toml.write_text('system = "cartpole"\ncontroller = "policy:net.pt"\n[vary]\nm_p = [0.1]\n')
    assert load_study_file(toml).controller == f"policy:{tmp_path / 'sub' / 'net.pt'}"


@pytest.mark.parametrize(("value", "expected"), [
    ("lqr,policy:missing.pt", "no such file"),
    ("lqr,policy:junk.pt", "not a PyTorch state dict"),
    ("lqr,policy:wrong.pt", "takes 3 observation(s)"),
    ("lqr,policy:", "expected policy:FILE"),
    ("lqr:net.pt", "--design-delay 'net.pt': expected a whole number of control periods"),
    ("mpc:soon", "--horizon 'soon': expected a whole number"),
    ("policy:net.pt,policy:sub/net.pt", "two files of one name"),
])
def test_a_bad_policy_is_one_line_exit_2_and_leaves_nothing(tmp_path, monkeypatch, capsys,
                                                            value, expected):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "junk.pt").write_bytes(b"not a network")
    torch.save(torch.nn.Sequential(torch.nn.Linear(3, 1)).state_dict(), tmp_path / "wrong.pt")
    (tmp_path / "sub").mkdir()
    for where in (tmp_path, tmp_path / "sub"):
        torch.save(torch.nn.Sequential(torch.nn.Linear(4, 1)).state_dict(), where / "net.pt")
    before = sorted(p.name for p in tmp_path.iterdir())
    code = main(["sweep", "cartpole", "--vary", f"controller={value}", "--runs", "2",
                 "--out", "s.parquet", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and expected in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before

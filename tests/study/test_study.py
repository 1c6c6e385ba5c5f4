"""Studies: descriptions, bad studies, the metrics of a point, files, resume, plots."""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow.parquet as pq
import pytest

from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.numeric.lookup import get_system
from equilibrist.sim.batch_inputs import child_seed, sample_uniform
from equilibrist.sim.controllers import LQG
from equilibrist.sim.noise import Noise
from equilibrist.sim.run import simulate
from equilibrist.study import StudyError, evaluate_point, make_study, read_study, run_study

SMALL = ["sweep", "cartpole", "--vary", "m_p=0.1:0.3:2", "--vary", "rate=100,200",
         "--runs", "6", "--duration", "1.5", "--x0", "theta=-0.2:0.2", "--seed", "7",
         "--no-progress"]


# -- bad studies: one line, exit 2, nothing written --------------------------------------

@pytest.mark.parametrize(("items", "expected"), [
    (["--vary", "m_q=0.1:0.3:2"], "unknown quantity 'm_q'"),
    (["--vary", "m_p=0.3:0.3:4"], "empty range"),
    (["--vary", "m_p=0.5:0.1:4"], "reversed range"),
    (["--vary", "m_p=-1:0.5:4"], "out of range"),
    (["--vary", "m_p=0.1:0.5:0"], "whole number >= 1"),
    (["--vary", "q.phi=0.1:1:3"], "no state 'phi'"),
    (["--vary", "controller=lqr,pid"], "'pid' is not a controller"),
    (["--vary", "rate=-5,100"], "not a positive sample rate"),
    (["--vary", "m_p=0.1:0.5:3", "--runs", "0"], "--runs"),
    (["--vary", "m_p=0.1:0.5:3", "--x0", "alpha=-1:1"], "no state 'alpha'"),
    (["--vary", "m_p=0.1:0.5:3", "--sample", "random:5"], "give the range only"),
])
def test_a_bad_study_is_one_line_exit_2_and_leaves_nothing(tmp_path, capsys, items, expected):
    out = tmp_path / "study.parquet"
    code = main(["sweep", "cartpole", *items, "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert len(err.strip().splitlines()) == 1, err
    assert expected in err
    assert list(tmp_path.iterdir()) == []


def test_every_problem_is_named_at_once():
    with pytest.raises(StudyError) as info:
        make_study("cartpole", vary={"m_p": "2:1:3", "l": "0.1:0.1:2", "bogus": "1:2:3"},
                   runs=0)
    text = str(info.value)
    for part in ("reversed range", "empty range", "'bogus'", "--runs"):
        assert part in text


def test_grid_points_are_every_combination_in_order():
    s = make_study("cartpole", vary=[("m_p", "0.1:0.3:3"), ("controller", "lqr,lqg")], runs=1)
    assert s.n_points == 6
    assert [s.point(i) for i in (0, 1, 5)] == [
        {"m_p": 0.1, "controller": "lqr"}, {"m_p": 0.1, "controller": "lqg"},
        {"m_p": 0.3, "controller": "lqg"}]
    logs = make_study("cartpole", vary={"rate": "50:800:5:log"}, runs=1)
    assert np.allclose([logs.point(i)["rate"] for i in range(5)], [50, 100, 200, 400, 800])


def test_random_points_depend_on_the_seed_and_index_only():
    a = make_study("cartpole", vary={"m_p": "0.1:0.5", "rate": "50:500:log"}, sample=40,
                   runs=1, seed=3)
    b = make_study("cartpole", vary={"m_p": "0.1:0.5", "rate": "50:500:log"}, sample=40,
                   runs=1, seed=3)
    pts = [a.point(i) for i in range(40)]
    assert pts == [b.point(i) for i in range(40)]
    m = np.array([p["m_p"] for p in pts])
    r = np.array([p["rate"] for p in pts])
    assert m.min() >= 0.1 and m.max() <= 0.5 and len(set(m)) == 40
    assert r.min() >= 50 and r.max() <= 500
    c = make_study("cartpole", vary={"m_p": "0.1:0.5", "rate": "50:500:log"}, sample=40,
                   runs=1, seed=4)
    assert c.point(0) != a.point(0)


# -- the metrics of one point against single runs -----------------------------------------

@pytest.mark.slow
def test_a_point_summarizes_the_same_runs_simulate_makes():
    """Rows from the compiled batch equal the metrics of each run simulated alone."""
    study = make_study("cartpole", vary={"m_p": [0.2], "q.theta": [0.1]}, runs=5,
                       duration=2.0, x0={"theta": "-0.25:0.25"}, spread={"l": 0.1}, seed=11,
                       batch_size=2)
    row = evaluate_point(study, 0)
    plant = get_system("cartpole", m_p=0.2)
    scales = plant.spec.design_scales
    q = [1 / scales[s] ** 2 if s != "theta" else 1 / 0.1**2 for s in plant.state_names]
    d = design(plant, q=q, rate=200.0)
    ctrl = LQG.from_design(d)
    x0s, spread = sample_uniform(plant, 5, ranges={"theta": (-0.25, 0.25)}, spread={"l": 0.1},
                                 seed=study.point_seed(0, 1), x_op=np.asarray(d.plant.x0))
    settling, peaks, costs, up = [], [], [], []
    qw = np.array([1 / scales[s] ** 2 for s in plant.state_names])
    rw = 1 / scales["F"] ** 2
    for k in range(5):
        batch_index, within = divmod(k, 2)
        res = simulate(plant.with_params(l=float(spread["l"][k])), ctrl, duration=2.0,
                       rate=200.0, x0=x0s[k], noise=Noise.from_design(d),
                       seed=child_seed(study.point_seed(0, 2, batch_index), within))
        m = res.metrics()
        up.append(not res.fell)
        settling.append(math.inf if m["settling_time"] is None else m["settling_time"])
        peaks.append(m["peak_input"]["F"])
        if not res.fell:
            dx = res.states - res.x_op
            du = res.applied - res.u_op
            costs.append(float(((dx**2 * qw).sum() + (du**2 * rw).sum()) / 200.0))
    assert row["status"] == "ok" and row["error"] is None
    assert row["runs"] == 5 and row["stayed_up"] == sum(up)
    assert row["fraction_up"] == sum(up) / 5
    assert row["settling_max"] == max(settling)
    assert row["settling_p50"] == sorted(settling)[2]
    assert row["settled_fraction"] == np.mean(np.isfinite(settling))
    assert row["peak_input_max.F"] == pytest.approx(max(peaks), rel=1e-12)
    assert row["cost_mean"] == pytest.approx(np.mean(costs), rel=1e-9)


def test_a_failed_design_is_a_row_not_an_abort(tmp_path):
    # 0.2 Hz is far too slow for the cart-pole: its design fails, the other point runs.
    study = make_study("cartpole", vary={"rate": [0.2, 200]}, runs=3, duration=1.0)
    done = run_study(study, tmp_path / "s.parquet")
    rows = pq.read_table(done.out).to_pylist()
    assert done.failed_points == 1
    assert rows[0]["status"] == "design failed" and "too slow" in rows[0]["error"]
    assert math.isnan(rows[0]["fraction_up"]) and rows[0]["runs"] == 0
    assert rows[1]["status"] == "ok" and rows[1]["runs"] == 3


def test_region_of_attraction_is_the_share_of_the_grid_caught_by_single_runs():
    study = make_study("cartpole", vary={"r.F": [20.0]}, runs=1, duration=2.0, noise="off",
                       controller="lqr", roa={"theta": "-0.9:0.9:7"}, metrics="basic")
    row = evaluate_point(study, 0)
    plant = get_system("cartpole")
    ctrl_design = design(plant, rate=200.0)
    from equilibrist.sim.controllers import StateFeedback

    ctrl = StateFeedback.from_design(ctrl_design)
    caught = [not simulate(plant, ctrl, duration=2.0, rate=200.0, x0={"theta": th}).fell
              for th in np.linspace(-0.9, 0.9, 7)]
    assert 0 < sum(caught) < 7  # the grid reaches past the region
    assert row["roa_fraction"] == sum(caught) / 7


# -- files: metadata, resume, identical bytes -----------------------------------------------

def test_table_is_tidy_with_the_study_and_versions_in_its_metadata(tmp_path, capsys):
    out = tmp_path / "s.parquet"
    assert main([*SMALL, "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 4 and summary["runs"] == 24
    table, study = read_study(out)
    assert table.num_rows == 4
    assert table.column("point").to_pylist() == [0, 1, 2, 3]
    assert table.column("m_p").to_pylist() == [0.1, 0.1, 0.3, 0.3]
    assert table.column("rate").to_pylist() == [100.0, 200.0, 100.0, 200.0]
    meta = pq.read_schema(out).metadata
    versions = json.loads(meta[b"equilibrist.versions"])
    assert set(versions) >= {"equilibrist", "numpy", "cc", "pyarrow"}
    assert study.seed == 7 and study.runs == 6
    assert not (tmp_path / "s.parquet.parts").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.parquet"]


def test_resume_computes_only_the_missing_chunks_and_gives_the_same_bytes(tmp_path, capsys):
    one = tmp_path / "one.parquet"
    assert main([*SMALL, "--out", str(one), "--chunk-size", "1"]) == 0
    two = tmp_path / "two.parquet"
    study = make_study("cartpole", vary=[("m_p", "0.1:0.3:2"), ("rate", "100,200")], runs=6,
                       duration=1.5, x0={"theta": "-0.2:0.2"}, seed=7)

    class Stop(Exception):
        pass

    def stop_after_two(chunk, done):
        if done == 2:
            raise Stop

    with pytest.raises(Stop):
        run_study(study, two, chunk_size=1, on_chunk=stop_after_two)
    parts = sorted(p.name for p in (tmp_path / "two.parquet.parts").iterdir())
    assert parts == ["chunk-000000.parquet", "chunk-000001.parquet", "study.json"]
    assert not two.exists()
    # Without --resume the unfinished study is not thrown away.
    capsys.readouterr()
    assert main([*SMALL, "--out", str(two), "--chunk-size", "1"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main([*SMALL, "--out", str(two), "--chunk-size", "1", "--resume", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["resumed_chunks"] == 2 and summary["computed_chunks"] == 2
    assert one.read_bytes() == two.read_bytes()
    # Another chunking, and a study file, give the same table too.
    toml = tmp_path / "study.toml"
    toml.write_text('system = "cartpole"\nruns = 6\nduration = 1.5\nseed = 7\n'
                    '[vary]\nm_p = {low = 0.1, high = 0.3, n = 2}\nrate = [100, 200]\n'
                    '[x0]\ntheta = [-0.2, 0.2]\n')
    three = tmp_path / "three.parquet"
    assert main(["sweep", "--study", str(toml), "--out", str(three), "--chunk-size", "3",
                 "--no-progress"]) == 0
    assert one.read_bytes() == three.read_bytes()


def test_resume_refuses_another_study(tmp_path, capsys):
    out = tmp_path / "s.parquet"
    study = make_study("cartpole", vary={"m_p": "0.1:0.3:2"}, runs=2, duration=0.5)

    def stop(chunk, done):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(study, out, chunk_size=1, on_chunk=stop)
    code = main(["sweep", "cartpole", "--vary", "m_p=0.1:0.3:2", "--runs", "3", "--duration",
                 "0.5", "--out", str(out), "--resume", "--chunk-size", "1", "--no-progress"])
    assert code == 2
    assert "another study" in capsys.readouterr().err


# -- pictures -----------------------------------------------------------------------------------

def test_plot_draws_heat_maps_and_lines_of_a_study(tmp_path, capsys):
    out = tmp_path / "s.parquet"
    assert main([*SMALL, "--vary", "controller=lqr,lqg", "--out", str(out)]) == 0
    heat = tmp_path / "heat.png"
    assert main(["plot", str(out), "--metric", "settling_p90", "--agg", "max",
                 "--out", str(heat)]) == 0
    line = tmp_path / "line.svg"
    assert main(["plot", str(out), "--x", "rate", "--where", "controller=lqr",
                 "--out", str(line)]) == 0
    from matplotlib.image import imread

    assert imread(heat).shape[:2] == (500, 700)
    assert "<svg" in line.read_text()
    capsys.readouterr()
    assert main(["plot", str(out), "--metric", "nonsense", "--out", str(heat)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--metric 'nonsense'" in err


def test_a_random_sample_from_the_command_line_is_drawn_and_plotted(tmp_path, capsys):
    out = tmp_path / "r.parquet"
    assert main(["sweep", "cartpole", "--vary", "m_p=0.1:0.4", "--vary", "rate=50:400:log",
                 "--sample", "random:5", "--runs", "2", "--duration", "0.5", "--metrics",
                 "basic", "--noise", "off", "--out", str(out), "--no-progress", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 5 and summary["study"]["sample"] == 5
    table, study = read_study(out)
    m_p = table.column("m_p").to_pylist()
    assert all(0.1 <= m <= 0.4 for m in m_p) and len(set(m_p)) == 5
    assert m_p == [study.point(i)["m_p"] for i in range(5)]
    # basic metrics leave the trajectory metrics out (NaN), never guessed
    assert all(math.isnan(v) for v in table.column("settling_p90").to_pylist())
    png = tmp_path / "r.png"
    assert main(["plot", str(out), "--out", str(png)]) == 0
    assert png.stat().st_size > 0


@pytest.mark.parametrize(("text", "extra", "expected"), [
    ('system = "cartpole"\nruns = 2\n[vary]\nm_p = "0.1:0.3:2"\nbogus = 1\n', [],
     "unknown quantity 'bogus'"),
    ('system = "cartpole"\nrunz = 2\n', [], "unknown key(s) runz"),
    ('system = "cartpole"\n[vary\n', [], "not valid TOML"),
    ('system = "cartpole"\n[vary]\nm_p = "0.1:0.3:2"\n', ["--runs", "3"], "drop --runs"),
])
def test_a_bad_study_file_is_one_line_exit_2(tmp_path, capsys, text, extra, expected):
    toml = tmp_path / "study.toml"
    toml.write_text(text)
    out = tmp_path / "s.parquet"
    assert main(["sweep", "--study", str(toml), *extra, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and expected in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.toml"]


def test_a_study_of_a_users_system_file(tmp_path, capsys):
    """A system file goes through a study as a catalogue system does (issue: bring your own robot)."""
    from pathlib import Path

    example = str(Path(__file__).resolve().parents[2] / "examples" / "my_cartpole.py")
    out = tmp_path / "mine.parquet"
    assert main(["sweep", example, "--vary", "m_p=0.1:0.2:2", "--runs", "8",
                 "--x0", "theta=-0.02:0.02", "--duration", "2", "--out", str(out), "--json"]) == 0
    capsys.readouterr()
    rows = pq.read_table(out).to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert [r["m_p"] for r in rows] == [0.1, 0.2]
    # The rig's LQG holds such small tilts: every run stays up.
    assert all(r["fraction_up"] == 1.0 for r in rows)

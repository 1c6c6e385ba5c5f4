"""URDFs as the field writes them: equilibrist's derived dynamics against Drake's MultibodyPlant.

    bash bench/peers_drake.sh                 # Drake in its own environment, once
    .venv/bin/python bench/bench_urdf_drake.py [--drake bench/_peers/drake/bin/python]

Each file is read unedited by both: equilibrist (through MuJoCo's compiler, the
symbolic derivation, the generated ``f``) and Drake (``Parser.AddModels`` into a
continuous ``MultibodyPlant``, no SceneGraph). At 200 seeded random states
(angles in [-pi, pi], slides in [-0.5, 0.5] m, rates in [-5, 5] per second) and
inputs (each motor's torque or force in [-5, 5]), the accelerations of
equilibrist's ``f`` are compared with Drake's ``EvalTimeDerivatives``, and the
mass matrices element by element: the largest difference relative to the
largest value. Drake ignores a URDF's joint ``friction`` (it warns), so a file
with friction is compared twice: at rest (rates zero, where the smooth Coulomb
law is zero) with its friction, and at every state with the friction
parameters set to zero. Files: the three of Drake's own examples that the
Drake wheel ships (held out: never used while writing the importer) and the
four written for the tests in that style (``tests/models``).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OURS = ["drake_acrobot.urdf", "drake_pendulum.urdf", "ros_cartpole.urdf", "rig_double_pendulum.urdf"]
HELD_OUT = ["acrobot/Acrobot.urdf", "acrobot/Acrobot_no_collision.urdf", "pendulum/Pendulum.urdf"]

# The Drake side, run in Drake's environment: one JSON request a line, one JSON answer a line.
PEER = r"""
import json, sys, warnings
import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.common import FindResourceOrThrow
for line in sys.stdin:
    req = json.loads(line)
    if req.get("find"):
        print(json.dumps({"path": FindResourceOrThrow("drake/examples/" + req["find"])}), flush=True)
        continue
    def build(welds):
        plant = MultibodyPlant(0.0)
        Parser(plant).AddModels(req["file"])
        for name in welds:
            plant.WeldFrames(plant.world_frame(), plant.GetFrameByName(name))
        plant.Finalize()
        return plant
    plant = build([])
    floating = [plant.get_body(b).name() for b in plant.GetFloatingBaseBodies()]
    if floating:  # a root not welded for Drake (no joint to world, or drake_ignore): welded, as Drake's examples do
        plant = build(floating)
    ctx = plant.CreateDefaultContext()
    joints = req["joints"]
    qi = [plant.GetJointByName(j).position_start() for j in joints]
    vi = [plant.GetJointByName(j).velocity_start() for j in joints]
    acts = [plant.get_joint_actuator(a) for a in plant.GetJointActuatorIndices()]
    out = {"qdd": [], "M": [], "effort": [a.effort_limit() for a in acts]}
    for x, u in zip(req["x"], req["u"]):
        n = len(joints)
        q = np.zeros(plant.num_positions()); v = np.zeros(plant.num_velocities())
        q[qi] = x[:n]; v[vi] = x[n:]
        plant.SetPositions(ctx, q); plant.SetVelocities(ctx, v)
        by_joint = dict(zip(req["driven"], u))
        plant.get_actuation_input_port().FixValue(ctx, np.array([by_joint[a.joint().name()] for a in acts]))
        d = plant.EvalTimeDerivatives(ctx).CopyToVector()
        out["qdd"].append(list(d[plant.num_positions():][vi]))
        m = plant.CalcMassMatrix(ctx)
        out["M"].append(m[np.ix_(vi, vi)].tolist())
    print(json.dumps(out), flush=True)
"""


def compare(peer: subprocess.Popen[str], path: Path, rng: np.random.Generator, n_states: int) -> dict[str, object]:
    from equilibrist.numeric.lookup import get_system

    def ask(request: dict[str, object]) -> dict[str, list]:  # type: ignore[type-arg]
        assert peer.stdin is not None and peer.stdout is not None
        peer.stdin.write(json.dumps(request) + "\n")
        peer.stdin.flush()
        return json.loads(peer.stdout.readline())  # type: ignore[no-any-return]

    system = get_system(str(path))
    spec = system.spec
    n = len(spec.coordinates)
    driven = [re.search(r"on joint (\w+)", i.meaning).group(1) for i in spec.inputs]  # type: ignore[union-attr]
    frictions = [p.name for p in spec.parameters if p.name.endswith("_friction")]
    low = np.array([-np.pi if spec.units[c] == "rad" else -0.5 for c in spec.coordinates])
    x = np.concatenate([rng.uniform(low, -low, (n_states, n)), rng.uniform(-5, 5, (n_states, n))], axis=1)
    u = rng.uniform(-5, 5, (n_states, len(driven)))
    row: dict[str, object] = {"file": path.name, "joints": n, "friction": bool(frictions)}
    cases = [("states", x, system.with_params(**dict.fromkeys(frictions, 0.0)) if frictions else system)]
    if frictions:
        rest = x.copy()
        rest[:, n:] = 0.0
        cases.append(("at rest, with friction", rest, system))
    for label, states, sys_ in cases:
        drake = ask({"file": str(path), "joints": list(spec.coordinates), "driven": driven,
                     "x": states.tolist(), "u": u.tolist()})
        ours = np.array([sys_.f(s, v)[n:] for s, v in zip(states, u, strict=True)])
        theirs = np.array(drake["qdd"])
        mass = np.zeros((n, n))
        ours_m = []
        for s in states:
            sys_.functions.mass_matrix(s, sys_.p, mass)
            ours_m.append(mass.copy())
        theirs_m = np.array(drake["M"])
        row[f"qdd {label}"] = float(np.abs(ours - theirs).max() / max(1.0, np.abs(theirs).max()))
        row[f"M {label}"] = float(np.abs(np.array(ours_m) - theirs_m).max() / np.abs(theirs_m).max())
        row["drake effort limits"] = drake["effort"]
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drake", default=str(HERE / "_peers" / "drake" / "bin" / "python"),
                    help="a Python with pydrake (bench/peers_drake.sh makes one)")
    ap.add_argument("--states", type=int, default=200)
    ap.add_argument("files", nargs="*", type=Path, help="more URDF files to compare (held out)")
    args = ap.parse_args()
    if not Path(args.drake).exists():
        print(f"no Drake at {args.drake}: run bash bench/peers_drake.sh first", file=sys.stderr)
        return 2
    peer = subprocess.Popen([args.drake, "-c", PEER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert peer.stdin is not None and peer.stdout is not None
    files = []
    for name in HELD_OUT:
        peer.stdin.write(json.dumps({"find": name}) + "\n")
        peer.stdin.flush()
        files.append(Path(json.loads(peer.stdout.readline())["path"]))
    files += [ROOT / "tests" / "models" / name for name in OURS] + list(args.files)
    rng = np.random.default_rng(47)
    rows = [compare(peer, f, rng, args.states) for f in files]
    peer.stdin.close()
    peer.wait()
    print(json.dumps(rows, indent=1))
    worst = max(v for r in rows for k, v in r.items() if k.startswith(("qdd", "M ")) and isinstance(v, float))
    print(f"largest relative difference: {worst:.2e}")
    return 0 if worst <= 1e-8 else 1


if __name__ == "__main__":
    sys.exit(main())

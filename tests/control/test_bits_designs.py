"""Every number a run takes from a design is the same bits under another BLAS kernel (what
another CPU would select): the swing-up's parameters, an LQG with a reference gain on a
six-state rig, the acrobot's predictor-form LQG (equilibrist.control.fixed)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

CODE = textwrap.dedent("""
    import hashlib
    from equilibrist.control.linear import LinearController
    from equilibrist.control.design import design
    from equilibrist.control.swingup import swingup
    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim import Noise
    h = hashlib.sha256()
    for name in ("cartpole", "furuta", "acrobot", "reaction_wheel_pendulum"):
        h.update(swingup(get_system(name), balance="lqg").params.tobytes())
    dc = get_system("double_cartpole")
    d = design(dc, rate=250.0)
    c = LinearController.from_design(d, kind="lqg", tracking=True)
    n = Noise.from_design(d)
    a = design(get_system("acrobot"), rate=100.0, kalman_form="predictor")
    for arr in (c.packed(), n.process_gain, n.process_intensity, n.measurement_covariance,
                LinearController.from_design(a, kind="lqg").packed()):
        h.update(arr.tobytes())
    print(h.hexdigest())
""")


def _digest(kernel: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    if kernel is not None:
        env["OPENBLAS_CORETYPE"] = kernel
    # A cache folder of its own: a design kept on disk would be read back, not made.
    env["EQUILIBRIST_CACHE"] = os.path.join(os.environ.get("TMPDIR", "/tmp"),
                                            f"equilibrist-bits-{kernel or 'default'}-{os.getpid()}")
    proc = subprocess.run([sys.executable, "-c", CODE], env=env, capture_output=True, text=True,
                          timeout=900, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip()


def test_designs_do_not_follow_the_blas_kernel() -> None:
    default, nehalem = _digest(None), _digest("Nehalem")
    assert len(default) == 64 and default == nehalem

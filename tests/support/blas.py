"""The same controller made under two BLAS kernels (what two CPUs would select): the bits of
its parameters, compared by the tests of the CPU-independent designs."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import textwrap
from collections.abc import Mapping

#: The kernels: the CPU's own choice, and OpenBLAS's Nehalem kernel (no AVX).
KERNELS = ("", "Nehalem")


def tvlqr_params_digests(options: Mapping[str, str], rate: float = 200.0) -> list[str]:
    """The SHA-256 of the cart-pole's tvlqr controller's parameters (``build_request`` with
    *options*) made in a fresh process under each of :data:`KERNELS`."""
    code = textwrap.dedent(f"""
        import hashlib
        from equilibrist.controllers.kinds import ControllerRequest
        from equilibrist.control.tvlqr import build_request
        from equilibrist.numeric.lookup import get_system
        ctrl = build_request(ControllerRequest(system=get_system("cartpole"), rate={rate!r},
                                               options={dict(options)!r}))
        print(hashlib.sha256(ctrl.params.tobytes()).hexdigest())
    """)
    digests = []
    for kernel in KERNELS:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if kernel:
            env["OPENBLAS_CORETYPE"] = kernel
        proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                              text=True, timeout=600, check=False)
        assert proc.returncode == 0, proc.stderr[-2000:]
        digests.append(proc.stdout.strip())
    assert all(len(d) == len(hashlib.sha256().hexdigest()) for d in digests), digests
    return digests

"""Processor in the loop on the Cortex-M4F: every kind in QEMU, in lockstep, against ``simulate``
(the MPC in ``test_run_mpc.py``).

The independent truths: ``simulate`` of the same controller in Python (the chip's commands
equal it within the chip's precision: float64 on the Cortex-M4F with the export in double,
float32 on the Uno whose ``double`` has 32 bits), simavr's own cycle counter beside the
firmware's count of its Timer1, the ELF's section headers read here beside the linker's
``size``, and the chips' published clocks and memories.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pil_runs import figures_are_the_chips, pil, same_commands


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["lqr", "lqg", "swingup", "tvlqr", "policy"])
def test_every_kind_runs_on_the_cortex_m4f_as_simulate(kind: str, tmp_path: Path) -> None:
    extra: tuple[str, ...] = ()
    if kind == "tvlqr":
        extra = ("--trajectory", _upright_plan(tmp_path))
    if kind == "policy":
        extra = ("--policy", _network(tmp_path))
    run = pil(kind, "cortex-m4f", *extra)
    same_commands(run, 1e-9)  # double in the export, float64 on the link
    figures_are_the_chips(run, 168_000_000, 1_048_576, 131_072)
    assert run.figures()["cycles_exact"] is False and run.fits


@pytest.mark.slow
def test_the_float_export_on_the_fpu_is_float32_close() -> None:
    run = pil("lqg", "cortex-m4f", "--precision", "float")
    same_commands(run, 1e-4)
    # Not the bits of double: the chip ran single precision.
    assert run.max_deviation is not None and run.max_deviation > 0


def _upright_plan(folder: Path) -> str:
    """A plan that holds the cart-pole upright for a second, saved as ``trajopt --out`` does."""
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.lookup import get_system

    cart = get_system("cartpole")
    op = cart.operating_point()
    knots = 10
    plan = Trajectory(
        system=cart.key, params=dict(cart.params), state_names=tuple(cart.spec.state_names),
        input_names=tuple(cart.spec.input_names), times=np.linspace(0.0, 1.0, knots + 1),
        states=np.tile(op.x, (knots + 1, 1)), inputs=np.tile(op.u, (knots + 1, 1)),
        mid_inputs=np.tile(op.u, (knots, 1)), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="held")
    return str(plan.save(folder / "upright.npz"))


def _network(folder: Path) -> str:
    """A small trained-policy network (a PyTorch state dict, 2 x 8 tanh units)."""
    import torch

    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 8),
                              torch.nn.Tanh(), torch.nn.Linear(8, 1))
    path = folder / "policy.pt"
    torch.save(net.state_dict(), path)
    return str(path)

"""Networks with a known answer: a policy that *is* the LQR, written in the policy's units."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from equilibrist.control.design import design
from equilibrist.numeric.lookup import get_system

#: The cart-pole's Bryson scales (its -v1 observation: each state over its scale, upright at 0)
#: and its force limit (the action 1 is 200 N).
CARTPOLE_SCALES = np.array([0.5, 0.2, 1.0, 1.0])
CARTPOLE_F_MAX = 200.0


def cartpole_lqr_network(path: str | Path, *, rate: float, gain: float = 1.0) -> np.ndarray:
    """Save to *path* the state dict of one ``Linear`` layer that is the cart-pole's LQR at
    *rate* times *gain* (u = -gain K x as a = W (x / scales), u = F_max a, unclipped while
    |u| < F_max); return the LQR's K."""
    k = design(get_system("cartpole"), rate=rate).K
    layer = torch.nn.Linear(4, 1).double()
    with torch.no_grad():
        layer.weight.copy_(torch.from_numpy(-gain * k * CARTPOLE_SCALES / CARTPOLE_F_MAX))
        layer.bias.zero_()
    torch.save(torch.nn.Sequential(layer).state_dict(), path)
    return np.asarray(k)

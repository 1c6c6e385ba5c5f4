"""Linearize the cart-pole at upright and look at its unstable pole.

Run: ``.venv/bin/python examples/linearize_cartpole.py``
"""

from __future__ import annotations

import numpy as np

from equilibrist import get_system


def main() -> None:
    cart = get_system("cartpole")
    lin = cart.linearize()
    print("states:", ", ".join(lin.state_names))
    print("A =\n", np.round(lin.A, 4))
    print("B =\n", np.round(lin.B, 4))
    unstable = [p for p in lin.poles if p.real > 0]
    print(f"unstable pole at {unstable[0].real:.3f} rad/s: the pole falls with a time constant "
          f"of {1 / unstable[0].real:.3f} s")
    heavier = cart.with_params(m_p=2.0).linearize()
    print(f"with a 2 kg pole the unstable pole moves to {max(heavier.poles.real):.3f} rad/s")


if __name__ == "__main__":
    main()

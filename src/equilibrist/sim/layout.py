"""The compiled core's calling convention, defined once.

Every array the core shares with Python has its slots, columns or rows
named here. :func:`constants` turns them into the ``_NAME = index`` values
that :mod:`equilibrist.sim.simcore` writes into each generated unit as
``#define EQ_NAME index`` (with the integrators' numbers and work rows from
:mod:`equilibrist.sim.integrators`), and the Python side
(:mod:`equilibrist.sim.setup`, :mod:`equilibrist.sim.run`,
:mod:`equilibrist.sim.batch`, :mod:`equilibrist.envs.core`) packs and reads
the same arrays through :class:`Slots` and :class:`Blocks`. The run's
argument struct is :data:`equilibrist.sim.core_unit.FIELDS`, written from there
for C and for ctypes both.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from equilibrist.native.linear_layout import linear_constants


@dataclass(frozen=True)
class Slots:
    """Named scalar slots of a 1-D array (``iopts``, ``fopts``, ``status``)."""

    prefix: str
    names: tuple[str, ...]

    def __getitem__(self, name: str) -> int:
        return self.names.index(name)

    def __len__(self) -> int:
        return len(self.names)

    def pack(self, dtype: type = float, **values: float) -> np.ndarray:
        """The array with every slot given by keyword (each exactly once)."""
        missing = [n for n in self.names if n not in values]
        extra = [n for n in values if n not in self.names]
        if missing or extra:
            raise TypeError(f"{self.prefix}: missing {missing}, unknown {extra}")
        return np.array([values[n] for n in self.names], dtype=dtype)

    def constants(self) -> dict[str, int]:
        return {f"_{self.prefix}_{n.upper()}": i for i, n in enumerate(self.names)}


_OFFSETS: dict[tuple[str, tuple[tuple[str, int], ...]], np.ndarray] = {}


@dataclass(frozen=True)
class Blocks:
    """Consecutive blocks of columns whose widths depend on the run's sizes.

    The core reads the start of each block from a small ``int64`` array
    (``offsets(...)``), indexed by the generated ``_<PREFIX>_<NAME>`` constants.
    """

    prefix: str
    blocks: tuple[tuple[str, str], ...]  # (name, size symbol: "n", "m", "ny", "1")

    def sizes(self, sizes: Mapping[str, int]) -> dict[str, int]:
        return {name: (1 if sym == "1" else int(sizes[sym])) for name, sym in self.blocks}

    def offsets(self, **sizes: int) -> np.ndarray:
        """Start column of each block, then the total width (``int64``; a new array)."""
        key = tuple(sorted(sizes.items()))
        known = _OFFSETS.get((self.prefix, key))
        if known is None:
            widths = self.sizes(sizes)
            known = np.zeros(len(self.blocks) + 1, dtype=np.int64)
            for i, (name, _sym) in enumerate(self.blocks):
                known[i + 1] = known[i] + widths[name]
            _OFFSETS[(self.prefix, key)] = known
        return known.copy()

    def slices(self, **sizes: int) -> dict[str, slice]:
        off = self.offsets(**sizes)
        return {name: slice(int(off[i]), int(off[i + 1])) for i, (name, _s) in enumerate(self.blocks)}

    def width(self, **sizes: int) -> int:
        return int(self.offsets(**sizes)[-1])

    def constants(self) -> dict[str, int]:
        out = {f"_{self.prefix}_{n.upper()}": i for i, (n, _s) in enumerate(self.blocks)}
        out[f"_{self.prefix}_END"] = len(self.blocks)
        return out


#: Integer options of a run: ``record`` the trajectory, ``accumulate`` the peaks and sums;
#: ``estimates`` whether the controller has an estimate (computed only for one of them).
IOPTS = Slots("IO", ("n_samples", "record", "delay", "n_sub", "integrator", "estimates",
                     "accumulate"))
#: Float options of a run (``rate`` gives the sample times ``t_k = k / rate``).
FOPTS = Slots("FO", ("h", "rtol", "atol", "rate"))
#: A run's status (``int64``): rows written, fell (0/1), the fell code, the physics step it fell.
STATUS = Slots("ST", ("rows", "fell", "fell_code", "fell_step"))
#: A row of a recorded trajectory.
RECORD = Blocks("REC", (("x", "n"), ("x_hat", "n"), ("y", "ny"), ("u_cmd", "m"),
                        ("u_sat", "m"), ("u_app", "m")))
#: A run's accumulators: peak |u_cmd|, sum u_app^2, samples saturated, peak |x - x_op|,
#: sum of squared estimation errors, peak |u_app|, and 1 + the last sample whose state was
#: outside the balance box (``bal``, equilibrist.tasks.balance_box; 0: never).
ACC = Blocks("ACC", (("peak_u", "m"), ("sum_u2", "m"), ("n_sat", "1"), ("peak_dx", "n"),
                     ("sum_est2", "n"), ("peak_u_app", "m"), ("last_out", "1")))
#: Rows of the per-run scratch array (``fell_x`` receives the state at a fall); the
#: integrator's work rows (:func:`equilibrist.sim.integrators.work_rows`) start at ``wk``.
SCRATCH = Slots("S", ("y", "x_hat", "u_cmd", "u_sat", "u_app", "z_new", "xprev", "ubuf", "wvec",
                      "zbuf", "pcur", "fell_x", "u_act", "wk"))
#: A rig's effects between the plant and the controller (:mod:`equilibrist.sim.rig`), in
#: ``rig_i``: any effect at all (``on``; 0: the core's path without them), the measurement's
#: and the actuation's delays [samples], the motor's torque response (0/1), the encoders
#: (0/1), the velocities' low-pass filter (0/1), and the coordinates (the state is
#: ``[q, q_dot]`` with ``nq`` of each); in ``rig_f``: the response's ``k`` per period, the
#: torque noise's and the velocity noise's standard deviations, the encoders' step and the
#: filter's ``a`` per period. A run's rig state (``rig_s``) is :func:`rig_state_len` doubles.
RIG_I = Slots("RI", ("on", "meas_delay", "act_delay", "response", "encoder", "filter", "nq"))
RIG_F = Slots("RF", ("response_k", "torque_sigma", "vel_sigma", "encoder_step", "filter_a"))


def rig_state_len(m: int, ny: int, nq: int, act_delay: int, meas_delay: int) -> int:
    """Doubles of one run's rig state: the motors' torques, the actuation's ring, the
    measurement's ring, the encoders' last positions and the filtered velocities (the C's
    ``eq_rig_len`` reads the same sizes)."""
    return m + m * (act_delay + 1) + ny * (meas_delay + 1) + nq + ny
#: The environments' settings (:mod:`equilibrist.envs.core` writes them): the slots of
#: ``ci``'s head (sizes, switches, and the offsets of ``cf``'s blocks and of ``ci``'s own
#: index blocks), of ``cf``'s head, and of a copy's ``us`` row after its four generator words.
ENV_CI = Slots("CI", (
    "n_sub", "n_samples", "observe_state", "reward", "physical", "chunks", "autoreset",
    "integrator",
    "ny", "nw", "nlv", "nhang", "nrnd", "np",
    "o_c_idx", "o_hang", "o_rnd_idx",
    "o_region", "o_op", "o_iscale", "o_start", "o_spread", "o_p_nom", "o_rnd_spread", "o_lv",
    "o_lw",
))
ENV_CF = Slots("CF", ("h", "dt", "bonus", "rtol", "atol"))
ENV_US = ("k", "auto")
#: Rows of an environment step's scratch; the integrator's work rows start at ``work``.
ENV_SCRATCH = Slots("ES", ("u", "w", "zbuf", "xprev", "work"))


def constants() -> dict[str, int]:
    """Every slot, column block and scratch row as a source constant (``_IO_DELAY = 2``...)."""
    out: dict[str, int] = {}
    for part in (IOPTS, FOPTS, STATUS, RECORD, ACC, SCRATCH, ENV_CI, ENV_CF, ENV_SCRATCH,
                 RIG_I, RIG_F):
        out.update(part.constants())
    out.update({f"_US_{name.upper()}": 4 + i for i, name in enumerate(ENV_US)})
    out["_US_WIDTH"] = 4 + len(ENV_US)
    out.update(linear_constants())
    return out


"""The vector environment's lanes (native/lanes.py): eight copies at once in AVX-512, the
bits of one copy at a time.

Independent truths: the same environment stepped one copy at a time (the core without
lanes), and, for the lanes' sine and cosine, libm's scalar eq_sin/eq_cos over every range
(first range, reduced, tiny, signed zeros, near multiples of pi/2, huge, NaN), compiled apart.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.envs import vector as vector_module
from equilibrist.envs.vector import EquilibristVectorEnv
from equilibrist.native import lanes
from equilibrist.numeric import libm


def _avx512() -> bool:
    flags = next((line for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("flags")), "")
    return all(f in flags.split() for f in ("avx512f", "avx512dq", "avx512vl", "avx512bw"))


def _trace(monkeypatch, with_lanes: bool, system: str, task: str, n: int, steps: int,
           scale: float, **options) -> tuple[list[np.ndarray], EquilibristVectorEnv]:
    original = vector_module.open_core
    monkeypatch.setattr(vector_module, "open_core",
                        functools.partial(lambda *a, **k: original(*a, **{**k, "lanes": with_lanes})))
    env = EquilibristVectorEnv(n, system, task, **options)
    monkeypatch.setattr(vector_module, "open_core", original)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    out = [obs.copy()]
    for _ in range(steps):
        action = rng.uniform(-scale, scale, (n, env.single_action_space.shape[0]))
        obs, reward, terminated, truncated, _ = env.step(action)
        out += [obs.copy(), reward.copy(), terminated.copy(), truncated.copy(), env.states.copy()]
    return out, env


@pytest.mark.parametrize(("system", "task", "options"), [
    ("cartpole", "balance", {}),  # sensor and process noise, falls and autoresets
    ("cartpole", "balance", {"noise": False, "physics_step": 0.02, "rate": 50}),
    ("cartpole", "swingup", {"randomize": {"m_p": 0.2}}),  # large angles: the reduction
    ("furuta", "balance", {}),
    ("acrobot", "swingup", {}),
], ids=["cartpole-noise", "cartpole-gym", "cartpole-swingup", "furuta", "acrobot"])
def test_lanes_give_the_bits_of_one_copy_at_a_time(monkeypatch, system, task, options) -> None:
    # 21 copies: two blocks of eight and five stepped one at a time.
    fast, env = _trace(monkeypatch, True, system, task, 21, 150, 1.0, **options)
    slow, plain = _trace(monkeypatch, False, system, task, 21, 150, 1.0, **options)
    assert env.core.kernel.lanes == (lanes.LANES if _avx512() else 1)
    assert plain.core.kernel.lanes == 1
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(a, b)
    ended = sum(int(t.sum()) for t in fast[3::5])
    if task == "balance":
        assert ended > 0  # autoresets happened inside the blocks


def test_a_dynamics_with_a_branch_is_not_widened() -> None:
    from equilibrist.native import pyc

    source = ("def f(x, u, p, out):\n    if x[0] > 0.0:\n        out[0] = x[1]\n"
              "    else:\n        out[0] = -x[1]\n")
    module = pyc.Module(source, prefix="t_")
    assert lanes.widen(module.function("f", ("F1", "F1", "F1", "F1"))) is None
    straight = pyc.Module("def f(x, u, p, out):\n    a = x[0]\n    out[0] = eq_sin(a) * eq_cos(a)\n",
                          prefix="t_")
    widened = lanes.widen(straight.function("f", ("F1", "F1", "F1", "F1")))
    assert widened is not None and "eqv_sincos(" in widened and "double" not in widened


HARNESS = r"""
static uint64_t st = 88172645463325252ull;
static double rnd(void) { st ^= st << 13; st ^= st >> 7; st ^= st << 17;
                          return (double)(st >> 11) * (1.0 / 9007199254740992.0); }
int main(void) {
    long bad = 0; int k, l;
    const double scales[] = {1e-9, 1e-7, 0.5, 0.8, 2.0, 10.0, 1e3, 1e5, 1e7, 1e300};
    for (k = 0; k < 400000; k++) {
        eqv x, s, c;
        for (l = 0; l < EQ_LANES; l++) x[l] = (2 * rnd() - 1) * scales[(k + l) % 10];
        if (k % 100 == 0) x[k % EQ_LANES] = 1.5707963267948966 * (k % 7);
        if (k % 99 == 0) x[k % EQ_LANES] = -0.0;
        if (k % 97 == 0) x[k % EQ_LANES] = NAN;
        if (k % 3 == 0) for (l = 0; l < EQ_LANES; l++) x[l] = (2 * rnd() - 1) * 0.78;
        eqv_sincos(x, &s, &c);
        for (l = 0; l < EQ_LANES; l++) {
            double a = eq_sin(x[l]), b = eq_cos(x[l]);
            bad += memcmp(&a, &s[l], 8) != 0 || memcmp(&b, &c[l], 8) != 0;
        }
    }
    printf("%ld\n", bad);
    return 0;
}
"""


def test_the_lanes_sine_and_cosine_are_libms_to_the_bit(tmp_path: Path) -> None:
    if shutil.which("gcc") is None:
        pytest.fail("gcc is needed (CI installs it)")
    # Compiled for AVX-512 where the CPU has it (as the lanes run), else for the machine's
    # baseline (GCC's vector operations lane by lane: the same arithmetic).
    target = lanes._PUSH_POP if _avx512() else "#define EQ_LANES_PUSH\n#define EQ_LANES_POP\n"
    text = ("#include <math.h>\n#include <stdint.h>\n#include <stdio.h>\n#include <string.h>\n"
            + libm.c_source() + target + lanes.PRELUDE + HARNESS)
    (tmp_path / "t.c").write_text(text)
    subprocess.run(["gcc", "-std=gnu99", "-O2", "-ffp-contract=off", "-fno-math-errno", "t.c",
                    "-o", "t", "-lm"], cwd=tmp_path, check=True, capture_output=True)
    out = subprocess.run([str(tmp_path / "t")], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "0"

"""A system is a value that travels: it pickles as its definition's content, so a batch's
worker processes and a later session rebuild it, a system defined in a script included (its
derivation's code and the helpers it calls travel by value), and the cache key of such a
definition covers every helper its derivation uses."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from equilibrist import get_system
from equilibrist.systems import files

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "my_cartpole.py"

# A script, as a user writes one: its own rig (the example's file, with the pole's length
# taken through a helper of the script), a Python controller, a batch in worker processes,
# and the system pickled for later.
SCRIPT = textwrap.dedent('''
    import dataclasses, pickle, sys
    import numpy as np
    from equilibrist.control.python_controller import PythonControllerBase
    from equilibrist.numeric.system import System
    from equilibrist.sim.batch import simulate_batch

    namespace = {}
    exec(compile(open(sys.argv[1]).read(), sys.argv[1], "exec"), namespace)
    SPEC = dataclasses.replace(namespace["SPEC"], name="scripted_cartpole")
    register_derive = namespace["derive"]


    def pole_length(d):
        return d.p["l"] * LENGTH_SCALE


    LENGTH_SCALE = 1.0


    def derive(d):
        assert pole_length(d) is not None
        return register_derive(d)


    class Hold(PythonControllerBase):
        rate = 200.0
        outputs = ("x", "theta", "x_dot", "theta_dot")

        def output(self, t, y, r):
            return np.array([-20.0 * y[0] + 60.0 * y[1] - 10.0 * y[2] + 8.0 * y[3]])


    if __name__ == "__main__":
        system = System.from_definition(SPEC, derive, m_p=0.15)
        x0 = {"theta": np.array([0.02, -0.03, 0.05, 0.01])}
        here = simulate_batch(system, Hold(), runs=4, duration=0.3, x0=x0, workers=1)
        there = simulate_batch(system, Hold(), runs=4, duration=0.3, x0=x0, workers=2)
        assert np.array_equal(here.final_state, there.final_state), "workers differ"
        with open(sys.argv[2], "wb") as fh:
            pickle.dump(system, fh)
        x, u = np.array([0.1, 0.2, -0.3, 0.4]), np.array([2.0])
        print(repr(system.f(x, u).tolist()), system.digest)
''')

READER = textwrap.dedent('''
    import pickle, sys
    import numpy as np
    system = pickle.load(open(sys.argv[1], "rb"))
    x, u = np.array([0.1, 0.2, -0.3, 0.4]), np.array([2.0])
    print(repr(system.f(x, u).tolist()), system.digest, system.params["m_p"], system.key)
''')


def _python(tmp_path: Path, code: str, *args: str) -> str:
    script = tmp_path / f"script_{abs(hash(code))}.py"
    script.write_text(code)
    done = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True,
                          timeout=600, check=False, env={**os.environ, "PYTHONHASHSEED": "0"})
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout.strip()


def test_a_scripted_system_runs_in_workers_and_comes_back_in_a_new_session(tmp_path: Path) -> None:
    # The script: a batch in worker processes (spawned: they never ran the script's main
    # block, so the system reaches them by value) equal to one in this process.
    pickled = tmp_path / "system.pickle"
    made = _python(tmp_path, SCRIPT, str(EXAMPLE), str(pickled))
    # A new session, which has never seen the script, reads the pickle: the same dynamics,
    # the same definition (its digest), the same parameter values.
    again = _python(tmp_path, READER, str(pickled))
    f_made, digest = made.rsplit(" ", 1)
    assert again == f"{f_made} {digest} 0.15 scripted_cartpole"


def test_catalogue_and_file_systems_pickle_as_their_keys() -> None:
    system = get_system("furuta", m_p=0.03)
    blob = pickle.dumps(system)
    assert b"sympy" not in blob and len(blob) < 2000  # the key and the values, no model
    back = pickle.loads(blob)
    assert back.key == "furuta" and back.params == system.params
    x = np.array([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(back.f(x, np.array([0.1])), system.f(x, np.array([0.1])))


def test_the_cache_key_covers_the_helpers_a_derivation_calls() -> None:
    """Two scripts whose derivations are the same text but whose helper differs are two
    definitions (the helper's source and the constants it reads are part of the content)."""
    def make(helper_body: str, constant: float) -> bytes:
        scope: dict[str, object] = {}
        exec(compile(textwrap.dedent(f'''
            SCALE = {constant!r}

            def helper(d):
                {helper_body}

            def derive(d):
                return helper(d)
        '''), "<a script>", "exec"), scope)
        return files._function_content(scope["derive"])  # type: ignore[arg-type]

    base = make("return d.p['l'] * SCALE", 1.0)
    assert base == make("return d.p['l'] * SCALE", 1.0)
    assert base != make("return d.p['l'] * SCALE * 2", 1.0)  # the helper's code
    assert base != make("return d.p['l'] * SCALE", 2.0)  # a constant the helper reads

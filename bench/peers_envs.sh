#!/usr/bin/env bash
# A separate environment with the environment peers of bench/bench_peers.py, all from the
# package index: Gymnasium (its vector CartPole), JAX with gymnax (on the CPU; gymnax imports
# six without declaring it) and EnvPool. They pin their own numpy and JAX, so they stay out of
# the project's .venv. (DAQP, the MPC's peer, is the project's own solver: the `mpc` extra.)
#   bash bench/peers_envs.sh            # creates bench/_peers/envs (about 1.7 GB)
# A peer that does not install here is left out (the bench says so); the others still run.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
env="$here/_peers/envs"
[ -x "$env/bin/python" ] || python3 -m venv "$env"
"$env/bin/pip" install --quiet --upgrade pip
"$env/bin/pip" install --quiet numpy gymnasium || exit 1
"$env/bin/pip" install --quiet "jax[cpu]" gymnax six || echo "gymnax: did not install" >&2
"$env/bin/pip" install --quiet envpool || echo "envpool: did not install" >&2
"$env/bin/python" - <<'PY'
import importlib
from importlib import metadata

for name in ("numpy", "gymnasium", "jax", "gymnax", "envpool"):
    try:
        importlib.import_module(name)
        print(name, metadata.version(name))
    except Exception as exc:  # a peer that does not import is reported
        print(name, "missing:", type(exc).__name__, str(exc).splitlines()[0] if str(exc) else "")
PY

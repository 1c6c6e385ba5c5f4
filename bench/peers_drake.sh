#!/usr/bin/env bash
# A separate environment with Drake (pip's `drake`, which brings SNOPT) for
# bench/bench_drake.py: Drake pins its own numpy, so it stays out of the project's .venv.
#   bash bench/peers_drake.sh            # creates bench/_peers/drake (about 200 MB)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
env="$here/_peers/drake"
[ -x "$env/bin/python" ] || python3 -m venv "$env"
"$env/bin/pip" install --quiet --upgrade pip
"$env/bin/pip" install --quiet drake
"$env/bin/python" -c "import pydrake; print('drake', pydrake.__version__ if hasattr(pydrake, '__version__') else '')"

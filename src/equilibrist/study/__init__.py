"""Studies: parameter and design sweeps, each point a batch of closed-loop runs.

A study (:func:`make_study`, or a TOML file read by :func:`load_study_file`)
is a grid or a random sample over physical parameters, design weights, the
control rate, the controller, the noise level and the delay; each point is
designed, simulated (the compiled batch core) and summarized into one row
of a Parquet table (:func:`run_study`), locally or on a Dask cluster, with
results that do not depend on where or how they were computed.

This package sits above the layers it ties together (``control``, ``sim``);
nothing below imports it. pyarrow (and Dask for clusters) are imported only
when a study runs: ``pip install 'equilibrist[cluster]'``.
"""

from equilibrist.study.compute import evaluate_point, metric_names
from equilibrist.study.record import Axis, Study, StudyError
from equilibrist.study.runner import StudyRun, default_chunk_size, run_study
from equilibrist.study.spec import load_study_file, make_study
from equilibrist.study.store import read_study

__all__ = [
    "Axis",
    "Study",
    "StudyError",
    "StudyRun",
    "default_chunk_size",
    "evaluate_point",
    "load_study_file",
    "make_study",
    "metric_names",
    "read_study",
    "run_study",
]

"""Gymnasium ids for every system and task, read from the catalogue.

The ids come from iterating the system registry and each spec's tasks
(:func:`equilibrist.tasks.spec_task_names`), so a system added to the
catalogue has its environments with nothing else to write. Reading specs
derives no model: registering is cheap.
"""

from __future__ import annotations

import warnings

import gymnasium as gym

from equilibrist.mechanics.spec import SystemSpec
from equilibrist.systems import registry
from equilibrist.tasks import TASK_NAMES, spec_task_names

NAMESPACE = "equilibrist"
#: The first id of every task; its ids keep their spaces and rewards.
VERSION = 0
#: Every version of the tasks, and the options an id of each passes: ``-v1`` is the
#: learnable form (:mod:`equilibrist.envs.learnable`), observing the whole state.
VERSION_OPTIONS: dict[int, dict[str, object]] = {0: {}, 1: {"version": 1, "observe": "state"}}
_ENTRY = "equilibrist.envs.env:EquilibristEnv"
_VECTOR_ENTRY = "equilibrist.envs.vector:EquilibristVectorEnv"


def _system_id(spec: SystemSpec) -> str:
    # A variant of a family (gyroscope[euler=xyz]) is named gyroscope_xyz.
    return spec.name if spec.variant is None else f"{spec.name}_{spec.variant[1]}"


def _system_arg(spec: SystemSpec) -> str:
    return spec.name


def catalogue_ids() -> dict[str, tuple[SystemSpec, str]]:
    """``{id: (spec, task)}`` for every system with an input and each of its tasks."""
    return {k: (spec, task) for k, (spec, task, _v) in _catalogue(VERSION).items()}


def _catalogue(version: int) -> dict[str, tuple[SystemSpec, str, int]]:
    out: dict[str, tuple[SystemSpec, str, int]] = {}
    for entry in registry.all_entries():
        spec = entry.spec
        for task in spec_task_names(spec):
            out[f"{NAMESPACE}/{_system_id(spec)}-{task}-v{version}"] = (spec, task, version)
    return out


def env_ids(version: int = VERSION) -> tuple[str, ...]:
    """Every registered id of *version*: the catalogue's, then the per-task ones taking
    ``system=``."""
    generic = tuple(f"{NAMESPACE}/{task}-v{version}" for task in TASK_NAMES)
    return (*_catalogue(version), *generic)


#: Gymnasium calls an id "out of date" when a higher version exists; ``-v0`` is not
#: retired: it keeps its spaces and rewards beside ``-v1``.
OUT_OF_DATE = r".*The environment equilibrist/\S+-v0 is out of date"


def register_all() -> None:
    """Register every id of every version with Gymnasium (again is harmless), and keep
    Gymnasium from calling the ``-v0`` ids out of date."""
    warnings.filterwarnings("ignore", message=OUT_OF_DATE, category=DeprecationWarning)
    for version, options in VERSION_OPTIONS.items():
        for env_id, (spec, task, _v) in _catalogue(version).items():
            kwargs: dict[str, object] = {"system": _system_arg(spec), "task": task, **options}
            if spec.variant is not None:  # the family by name, its variant by its option
                option, variant = spec.variant
                kwargs["params"] = {option: variant}
            _register(env_id, kwargs)
        for task in TASK_NAMES:
            _register(f"{NAMESPACE}/{task}-v{version}", {"task": task, **options})


def _register(env_id: str, kwargs: dict[str, object]) -> None:
    if env_id in gym.registry:
        return
    gym.register(id=env_id, entry_point=_ENTRY, vector_entry_point=_VECTOR_ENTRY,
                 kwargs=kwargs, disable_env_checker=False)


__all__ = ["NAMESPACE", "VERSION_OPTIONS", "catalogue_ids", "env_ids", "register_all"]

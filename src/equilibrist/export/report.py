"""What a controller's exporter reports: the fields the command line prints."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from equilibrist.native.size import Footprint


@dataclass(frozen=True)
class Described:
    """What the command line's report reads of an exported controller (id, kind, rate)."""

    fingerprint: str
    controller: str
    rate: float


@dataclass(frozen=True)
class Steps:
    """How many recorded samples the export's test replays."""

    n_steps: int


@dataclass(frozen=True)
class ControllerExport:
    """What a controller's exporter wrote (an :class:`~equilibrist.export.writer.ExportReport`)."""

    folder: Path
    name: str
    files: Mapping[str, str]
    precision: str
    data: Described
    vectors: Steps
    #: What ``make size`` printed at export (None: not measured, see :attr:`size_note`).
    footprint: Footprint | None = None
    size_note: str = ""
    #: DAQP's worst iteration counts (the MPC's export only).
    iterations: Mapping[str, int] | None = None

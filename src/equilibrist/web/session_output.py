"""What a playground session sends: the frames for the page (shapes that changed, chart
samples, the margin to a fall) and the downloads (the last run as a result, CSV or NPZ, the
C export of the controller in force); a base of :class:`equilibrist.web.session.Session`.
"""

from __future__ import annotations

import io
import math
import zipfile
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.web.runners import Runner
from equilibrist.web.session_design import SessionError, Settings
from equilibrist.web.session_loop import _Loop, _Record

if TYPE_CHECKING:
    from pathlib import Path

    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult
    from equilibrist.viz.drawing import Scene


#: Digits of the drawing's coordinates sent to the page.
DIGITS = 5
#: Frames a page that reports what it has drawn may be behind before frames are held back.
MAX_UNSEEN = 12
#: Chart samples kept for a page that is behind (the oldest are dropped).
MAX_CHART_SAMPLES = 2000


class _SessionOutput:
    """The frames and downloads of a :class:`~equilibrist.web.session.Session` (its base)."""

    # What these methods read of the session (set by Session).
    system: System
    settings: Settings
    scene: Scene
    loop: _Loop
    record: _Record
    state_names: tuple[str, ...]
    region_idx: np.ndarray
    region_lo: np.ndarray
    region_hi: np.ndarray
    x: np.ndarray
    xhat: np.ndarray
    u_cmd: np.ndarray
    u_app: np.ndarray
    u_low: np.ndarray
    u_high: np.ndarray
    t: float
    run: int
    frame_no: int
    seen: int | None
    paused: bool
    fell: dict[str, float | str] | None
    mode: str | None
    mode_since: float
    hanging: bool
    push_value: float
    pushes: int
    push_seq: int | None
    messages: list[dict[str, object]]
    sent_shapes: dict[str, tuple[object, ...]]
    chart_t: list[float]
    chart_x: list[list[float]]
    chart_xhat: list[list[float]]
    chart_u: list[list[float]]

    # -- output ---------------------------------------------------------------------------------
    def margin(self) -> dict[str, object] | None:
        """How far the state is from leaving its region: ``1`` at the centre, ``0`` at the edge."""
        if not self.region_idx.size:
            return None
        v = self.x[self.region_idx]
        half = (self.region_hi - self.region_lo) / 2
        centre = (self.region_hi + self.region_lo) / 2
        frac = 1.0 - np.abs(v - centre) / half
        i = int(np.argmin(frac))
        return {"fraction": float(np.clip(frac[i], 0.0, 1.0)) if np.isfinite(frac[i]) else 0.0,
                "state": self.state_names[int(self.region_idx[i])]}

    def behind(self) -> bool:
        """Whether the page is too far behind to be sent another frame now.

        A page that reports the frames it drew (``seen``) gets frames no
        faster than it draws them; the chart samples wait for the next frame
        it gets. A client that never reports gets every frame.
        """
        if self.seen is None or self.frame_no - self.seen <= MAX_UNSEEN:
            return False
        if len(self.chart_t) > MAX_CHART_SAMPLES:
            cut = len(self.chart_t) - MAX_CHART_SAMPLES
            del self.chart_t[:cut], self.chart_x[:cut], self.chart_xhat[:cut], self.chart_u[:cut]
        return True

    def frame(self) -> dict[str, object]:
        """The ``frame`` message for the page (and clears the chart samples sent)."""
        shapes = []
        for s in self.scene.shapes(self.x, self.u_app):
            raw = np.asarray(s.points, float)
            sig = (s.kind, s.color, s.z, s.text, s.edge, s.width, raw.tobytes())
            if self.sent_shapes.get(s.key) == sig:
                continue  # unchanged since the last frame: the page keeps it
            self.sent_shapes[s.key] = sig
            shapes.append({"key": s.key, "kind": s.kind, "points": wire_points(raw), "color": s.color,
                           "width": s.width, "z": s.z, "text": s.text, "edge": s.edge,
                           "bounds": s.bounds})
        self.frame_no += 1
        out = {
            "type": "frame",
            "n": self.frame_no,
            "run": self.run,
            "t": round(self.t, 6),
            "x": self.x.tolist(),
            "xhat": self.xhat.tolist(),
            "u": self.u_app.tolist(),
            "u_cmd": np.asarray(self.u_cmd).tolist(),
            "u_limits": [self.u_low.tolist(), self.u_high.tolist()],
            "push": self.push_value,
            "pushes": self.pushes,
            "push_seq": self.push_seq,
            "paused": self.paused,
            "fell": self.fell,
            "margin": self.margin(),
            "controller": self.settings.controller,
            "mode": self.mode,
            "mode_since": round(self.mode_since, 4),
            "hanging": self.hanging,
            "solve": self.loop.runner.solve_stats() if self.loop.runner is not None else None,
            "shapes": shapes,
            "samples": {"t": self.chart_t, "x": self.chart_x, "xhat": self.chart_xhat,
                        "u": self.chart_u},
        }
        self.chart_t, self.chart_x, self.chart_xhat, self.chart_u = [], [], [], []
        return out

    def take_messages(self) -> list[dict[str, object]]:
        out, self.messages = self.messages, []
        return out

    # -- downloads ----------------------------------------------------------------------------
    def last_run(self) -> SimResult:
        """The samples since the last reset, rate change or new system, as a result."""
        from equilibrist.sim.result import SimResult

        rec = self.record
        if rec.rows == 0:
            raise SessionError("nothing has run yet: let the system run a moment first")
        system = self.system
        m = system.n_inputs
        return SimResult(
            system=system.key,
            system_digest=system.digest,
            params=dict(system.params),
            state_names=system.state_names,
            state_units=system.state_units,
            input_names=system.input_names,
            input_units=system.input_units,
            output_names=self.loop.outputs,
            reference_names=(),
            time=rec.ordered(rec.time),
            states=rec.ordered(rec.states),
            estimates=rec.ordered(rec.estimates),
            measurements=rec.ordered(rec.measurements),
            commanded=rec.ordered(rec.commanded),
            saturated=rec.ordered(rec.saturated),
            applied=rec.ordered(rec.applied),
            reference=np.zeros((rec.rows, 0)),
            x_op=self.loop.x_op,
            u_op=self.loop.u_op,
            fell=self.fell is not None,
            fell_at=None if self.fell is None else float(self.fell["at"]),
            fell_state=None if self.fell is None else str(self.fell["state"]),
            fell_x=None if self.fell is None else self.x.copy(),
            final_state=self.x.copy(),
            settings={"source": "playground", "rate": self.settings.rate,
                      "controller": {"kind": self.settings.controller},
                      "playground": self.settings.to_dict(), "inputs": m},
        )

    def run_file(self, kind: str, result: SimResult | None = None) -> bytes:
        """The last run (or *result*, the copy :meth:`last_run` made) as ``"csv"`` or ``"npz"`` bytes.

        The server takes the copy on its event loop, where the samples are
        added, and writes it in another thread: read from there, the record
        could gain a row between its time and its states.
        """
        import tempfile
        from pathlib import Path

        if result is None:
            result = self.last_run()
        with tempfile.TemporaryDirectory(prefix="equilibrist-play-") as tmp:
            path = Path(tmp) / f"run.{kind}"
            written = result.to_csv(path) if kind == "csv" else result.save(path)
            return written.read_bytes()

    def export_zip(self) -> bytes:
        """The C export of the controller in force, as a zip archive."""
        from equilibrist.export.data import controller_data
        from equilibrist.export.folder import generator_version
        from equilibrist.export.vectors import record
        from equilibrist.export.writer import _describe, render

        kind = self.settings.controller
        if kind == "off":
            raise SessionError("the controller is off: pick LQG, LQR, swing-up or MPC to export it")
        if self.loop.runner is not None:
            return self._export_runner(self.loop.runner)
        d, system = self.loop.design, self.system
        data = controller_data(d, controller=kind)
        vectors = record(d, system, controller=kind, precision="double")
        title, table = _describe(system, data)
        files = render(data, vectors, precision="double", version=generator_version(),
                       title=title, param_table=table)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for rel, (text, _what) in files.items():
                zf.writestr(f"{data.name}/{rel}", text)
        return buf.getvalue()

    def _export_runner(self, runner: Runner) -> bytes:
        """The swing-up's or the MPC's C export (``equilibrist export --controller ...``), zipped."""
        import tempfile
        from pathlib import Path

        from equilibrist.web.runners import export_folder

        top = f"{self.system.name}_{runner.kind}"
        with tempfile.TemporaryDirectory(prefix="equilibrist-play-") as tmp:
            folder = Path(tmp) / top
            export_folder(runner, self.system, str(folder))
            return _zip_folder(folder, top)


def wire_points(points: object) -> list[float | None]:
    """A shape's points as the page gets them: flat, rounded to :data:`DIGITS`, a NaN (a
    break in a polyline) as null."""
    pts = np.round(np.asarray(points, float), DIGITS).reshape(-1).tolist()
    return [None if math.isnan(v) else v for v in pts]


def _zip_folder(folder: Path, top: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                zf.write(path, f"{top}/{path.relative_to(folder).as_posix()}")
    return buf.getvalue()

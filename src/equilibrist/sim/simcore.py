"""The simulation core loaded: :func:`load_core` compiles the unit that
:mod:`equilibrist.sim.core_unit` writes for a system and a controller
(:mod:`equilibrist.native.build`: cached by content, atomic, checked), and
:class:`NativeCore` calls its entries with the run's argument struct.
"""


from __future__ import annotations

import ctypes
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.nonlinear import NonlinearController
from equilibrist.native import build
from equilibrist.numeric.system import System
from equilibrist.sim import integrators
from equilibrist.sim.core_unit import FIELDS, RunArgs, unit_inputs, unit_source

#: The core's C sources (core.c, integrators.c, env.c, shoot.c), in the package that writes C.
_C_FOLDER = Path(build.__file__).parent

if TYPE_CHECKING:
    from equilibrist.sim.rig import Rig
    from equilibrist.sim.steps import PlantSteps

def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None or a.size == 0 else int(a.ctypes.data)


class NativeCore:
    """One compiled core: its entries, called with numpy arrays.

    Arrays that the core writes must be C-contiguous and of the core's
    dtype (float64, int64 or uint64); the others are converted if needed.
    """

    def __init__(self, system: System, key: bytes | tuple[int, ...] | None,
                 controller: NonlinearController | None = None, *, lanes: bool = False) -> None:
        self.system = system
        self.key = key
        #: Copies the vector environment's step runs at once here (native/lanes.py).
        self.lanes = 1
        stem = f"{system.compiled.module_path.stem}_core"
        system.compiled.functions  # noqa: B018  # a damaged generated module is rebuilt first
        self.lib, self.path = build.load(
            lambda: unit_source(system, key, controller, lanes=lanes), stem,
            inputs=unit_inputs(system, key, controller, lanes=lanes))
        lib = self.lib
        args_p = ctypes.POINTER(RunArgs)
        lib.eq_run_one.argtypes = [args_p]
        lib.eq_run_one.restype = ctypes.c_int
        lib.eq_run_many.argtypes = [args_p]
        lib.eq_run_many.restype = ctypes.c_int
        vp, i64 = ctypes.c_void_p, ctypes.c_int64
        lib.eq_measure_one.argtypes = [vp, vp, i64, vp, i64, vp, vp]
        lib.eq_measure_one.restype = None
        lib.eq_scratch_rows.argtypes = []
        lib.eq_scratch_rows.restype = i64
        lib.eq_scratch_width.argtypes = [i64, i64, i64]
        lib.eq_scratch_width.restype = i64
        lib.eq_advance_one.argtypes = [args_p, i64, vp, vp]
        lib.eq_rig_measure_one.argtypes = [args_p, i64, vp, vp, vp, vp]
        lib.eq_rig_measure_one.restype = None
        lib.eq_rig_actuate_one.argtypes = [args_p, i64, vp, vp, vp, vp, vp]
        lib.eq_rig_actuate_one.restype = None
        lib.eq_advance_one.restype = ctypes.c_int
        lib.eq_rk4_steps.argtypes = [vp, vp, vp, ctypes.c_double, i64]
        lib.eq_rk4_steps.restype = None
        lib.eq_normals_into.argtypes = [vp, vp, i64]
        lib.eq_normals_into.restype = None
        lib.eq_f_one.argtypes = [vp, vp, vp, vp]
        lib.eq_f_one.restype = None
        if not hasattr(lib, "eq_env_step_many"):
            return  # a core made for one controller: the closed loop only
        lib.eq_env_lanes.argtypes = []
        lib.eq_env_lanes.restype = i64
        self.lanes = int(lib.eq_env_lanes())
        lib.eq_env_step_many.argtypes = [vp, vp, vp, vp, i64, vp, vp, i64, vp, vp, i64]
        lib.eq_env_step_many.restype = i64
        lib.eq_env_step_one.argtypes = [vp, vp, vp, vp, vp, vp, vp]
        lib.eq_env_step_one.restype = ctypes.c_double
        lib.eq_env_begin_one.argtypes = [vp, vp, vp, vp, vp]
        lib.eq_env_begin_one.restype = None
        lib.eq_env_reset_many.argtypes = [vp, vp, vp, i64, i64, vp, vp]
        lib.eq_env_reset_many.restype = None
        f64 = ctypes.c_double
        lib.eq_shoot_many.argtypes = [i64, f64, f64, vp, i64, i64, vp, vp, i64, vp, i64, vp, vp,
                                      vp, i64, vp, vp]
        lib.eq_shoot_many.restype = None
        lib.eq_innovations.argtypes = [i64, f64, f64, vp, vp, vp, i64, vp, vp, vp, i64, vp, vp,
                                       vp, vp]
        lib.eq_innovations.restype = None

    # -- the shared argument struct ------------------------------------------------------------
    @staticmethod
    def _arrays(values: dict[str, Any]) -> tuple[RunArgs, list[np.ndarray]]:
        keep: list[np.ndarray] = []
        args = RunArgs()
        for name, kind in FIELDS:
            if name not in values:
                continue
            v = values[name]
            if kind == "i":
                setattr(args, name, int(v))
                continue
            if v is None:
                continue
            dtype = {"pf": np.float64, "pi": np.int64, "vi": np.int64, "pu": np.uint64}[kind]
            arr = np.asarray(v)
            if arr.dtype != dtype or not arr.flags.c_contiguous:
                arr = np.ascontiguousarray(arr, dtype=dtype)
            keep.append(arr)
            setattr(args, name, _ptr(arr))
        return args, keep

    @staticmethod
    def _out(arr: np.ndarray, dtype: type[np.generic], what: str) -> np.ndarray:
        if arr.dtype != dtype or not arr.flags.c_contiguous or not arr.flags.writeable:
            raise TypeError(f"the core writes {what}: it must be a writable C-contiguous "
                            f"{np.dtype(dtype).name} array")
        return arr

    def _common(self, *, op: np.ndarray, c_idx: np.ndarray, cp: np.ndarray, ref: np.ndarray,
                uff: np.ndarray, lv: np.ndarray, lw: np.ndarray, p_switch: np.ndarray,
                region: np.ndarray, kicks: np.ndarray, kick_value: np.ndarray,
                pulses: np.ndarray, pulse_value: np.ndarray, rec_cols: np.ndarray,
                acc_cols: np.ndarray, iopts: np.ndarray, fopts: np.ndarray,
                bal: np.ndarray | None = None) -> dict[str, object]:
        ref = np.asarray(ref, dtype=float)
        lv = np.asarray(lv, dtype=float)
        lw = np.asarray(lw, dtype=float)
        return dict(
            iopts=iopts, fopts=fopts, op=op, c_idx=c_idx, ny=len(c_idx), cp=cp, ncp=len(cp),
            ref=ref, nr=(ref.shape[1] if ref.ndim == 2 else 0), uff=uff, lv=lv,
            nlv=lv.shape[0], lw=lw, nw=(lw.shape[1] if lw.ndim == 2 else 0),
            p_switch=p_switch, n_sets=len(p_switch), region=region, kicks=kicks,
            n_kicks=len(kicks), kick_value=kick_value, pulses=pulses, n_pulses=len(pulses),
            pulse_value=pulse_value, rec_cols=rec_cols, acc_cols=acc_cols,
            bal=bal, nbal=0 if bal is None else 1,
        )

    @staticmethod
    def _rig(rig_i: np.ndarray | None, rig_f: np.ndarray | None,
             gforce: np.ndarray | None) -> dict[str, object]:
        """The rig's fields of the argument struct (none: NULL, the core's path without)."""
        if gforce is not None and gforce.size == 0:
            gforce = None
        if gforce is not None and rig_i is None:
            raise TypeError("generalized forces need the rig's options (the coordinates)")
        return dict(rig_i=rig_i, rig_f=rig_f, gforce=gforce,
                    n_gforce=0 if gforce is None else gforce.shape[-2])

    def run_one(self, k_start: int, k_end: int, iopts: np.ndarray, fopts: np.ndarray,
                x: np.ndarray, z: np.ndarray, u_prev: np.ndarray, rng: np.ndarray,
                op: np.ndarray, c_idx: np.ndarray, cp: np.ndarray, ref: np.ndarray,
                uff: np.ndarray, lv: np.ndarray, lw: np.ndarray, p_sets: np.ndarray,
                p_switch: np.ndarray, lin_s: np.ndarray, region: np.ndarray,
                kicks: np.ndarray, kick_value: np.ndarray, pulses: np.ndarray,
                pulse_value: np.ndarray, rec_cols: np.ndarray, acc_cols: np.ndarray,
                rec: np.ndarray, acc: np.ndarray, status: np.ndarray, fell_x: np.ndarray,
                stop: np.ndarray, rig_i: np.ndarray | None = None,
                rig_f: np.ndarray | None = None, rig_s: np.ndarray | None = None,
                gforce: np.ndarray | None = None) -> None:
        """One closed-loop run, or samples *k_start* .. *k_end* - 1 of one (``eq_run_one``:
        *x*, *z*, *u_prev*, *rng*, *rec*, *acc*, *status*, *fell_x* written in place; a rig's
        effects in *rig_i*, *rig_f* (:data:`~equilibrist.sim.layout.RIG_I`, ``RIG_F``), its
        state *rig_s* written in place, and the generalized forces *gforce*
        ``(samples, nq)``)."""
        values = self._common(op=op, c_idx=c_idx, cp=cp, ref=ref, uff=uff, lv=lv, lw=lw,
                              p_switch=p_switch, region=region, kicks=kicks,
                              kick_value=kick_value, pulses=pulses, pulse_value=pulse_value,
                              rec_cols=rec_cols, acc_cols=acc_cols, iopts=iopts, fopts=fopts)
        for arr, dtype, what in ((x, np.float64, "x"), (z, np.float64, "z"),
                                 (u_prev, np.float64, "u_prev"), (rng, np.uint64, "rng"),
                                 (rec, np.float64, "rec"), (acc, np.float64, "acc"),
                                 (status, np.int64, "status"), (fell_x, np.float64, "fell_x"),
                                 (stop, np.int64, "stop")):
            self._out(arr, dtype, what)
        p_sets = np.asarray(p_sets, dtype=float)
        values.update(k_start=k_start, k_end=k_end, x=x, z=z, nz=len(z), u_prev=u_prev, rng=rng,
                      p_sets=p_sets, p_len=p_sets.shape[1], lin_s=lin_s, rec=rec,
                      rec_w=rec.shape[1] if rec.ndim == 2 else 0, acc=acc, status=status,
                      fell_x=fell_x, stop=stop)
        if rig_s is not None:
            self._out(rig_s, np.float64, "rig_s")
        values.update(self._rig(rig_i, rig_f, gforce), rig_s=rig_s)
        args, keep = self._arrays(values)
        if self.lib.eq_run_one(ctypes.byref(args)) != 0:
            raise MemoryError("the simulation core ran out of memory")
        del keep

    def run_many(self, iopts: np.ndarray, fopts: np.ndarray, x0s: np.ndarray,
                 z0: np.ndarray, rngs: np.ndarray, op: np.ndarray, c_idx: np.ndarray,
                 cp: np.ndarray, ref: np.ndarray, uff: np.ndarray, lv: np.ndarray,
                 lw: np.ndarray, p_sets_r: np.ndarray, p_switch: np.ndarray,
                 lin_r: np.ndarray, region: np.ndarray, kicks: np.ndarray,
                 kick_value: np.ndarray, pulses: np.ndarray, pulse_value: np.ndarray,
                 rec_cols: np.ndarray, acc_cols: np.ndarray, recs: np.ndarray,
                 accs: np.ndarray, statuses: np.ndarray, fell_xs: np.ndarray,
                 x_ends: np.ndarray, stop: np.ndarray, threads: int = 1,
                 bal: np.ndarray | None = None, rig_i: np.ndarray | None = None,
                 rig_f: np.ndarray | None = None, gforce: np.ndarray | None = None) -> None:
        """Independent runs from *x0s*, in parallel on *threads* threads (``eq_run_many``:
        the per-run blocks of *recs*, *accs*, *statuses*, *fell_xs*, *x_ends* written; *bal*
        the balance box whose last exit each run's accumulators keep; a rig's effects in
        *rig_i*, *rig_f*, and each run's generalized forces in *gforce*
        ``(runs, samples, nq)``)."""
        values = self._common(op=op, c_idx=c_idx, cp=cp, ref=ref, uff=uff, lv=lv, lw=lw,
                              p_switch=p_switch, region=region, kicks=kicks,
                              kick_value=kick_value, pulses=pulses, pulse_value=pulse_value,
                              rec_cols=rec_cols, acc_cols=acc_cols, iopts=iopts, fopts=fopts,
                              bal=bal)
        for arr, dtype, what in ((recs, np.float64, "recs"), (accs, np.float64, "accs"),
                                 (statuses, np.int64, "statuses"),
                                 (fell_xs, np.float64, "fell_xs"),
                                 (x_ends, np.float64, "x_ends"), (stop, np.int64, "stop")):
            self._out(arr, dtype, what)
        runs = len(x0s)
        if runs == 0:
            return
        p_sets_r = np.asarray(p_sets_r, dtype=float)
        lin_r = np.asarray(lin_r, dtype=float)
        values.update(n_runs=runs, n_threads=max(1, int(threads)), x0s=x0s, rngs=rngs,
                      z=np.asarray(z0, dtype=float), nz=len(z0), p_sets=p_sets_r,
                      p_len=p_sets_r.shape[2], lin_s=(lin_r if lin_r.size else None),
                      rec=(recs if recs.size else None), rec_w=recs.shape[2], acc=accs,
                      acc_w=accs.shape[1], status=statuses, fell_x=fell_xs, x_ends=x_ends,
                      stop=stop)
        values.update(self._rig(rig_i, rig_f, gforce))
        args, keep = self._arrays(values)
        if self.lib.eq_run_many(ctypes.byref(args)) != 0:
            raise MemoryError("the simulation core ran out of memory")
        del keep

    def measurer(self, *, x: np.ndarray, c_idx: np.ndarray, lv: np.ndarray, rng: np.ndarray,
                 y: np.ndarray) -> Callable[[], None]:
        """``measure()``: the sensors of *x* into *y*, with the noise ``lv z`` drawn from
        *rng* (the arrays kept by reference, their addresses taken once)."""
        self._out(x, np.float64, "x")
        self._out(rng, np.uint64, "rng")
        self._out(y, np.float64, "y")
        c_idx = np.ascontiguousarray(c_idx, dtype=np.int64)
        lv = np.ascontiguousarray(lv, dtype=float)
        fn = self.lib.eq_measure_one
        args = (_ptr(x), _ptr(c_idx), len(c_idx), _ptr(lv), lv.shape[0] if lv.ndim == 2 else 0,
                _ptr(rng), _ptr(y))
        held = (x, c_idx, lv, rng, y)

        def measure(_held: tuple[np.ndarray, ...] = held) -> None:  # the arrays live as long as it
            fn(*args)

        return measure

    def rig_steps(self, *, x: np.ndarray, c_idx: np.ndarray, lv: np.ndarray, op: np.ndarray,
                  fopts: np.ndarray, rig_i: np.ndarray, rig_f: np.ndarray, rig_s: np.ndarray,
                  rng: np.ndarray, y: np.ndarray, u_app: np.ndarray, u_act: np.ndarray,
                  lim: np.ndarray) -> tuple[Callable[[int], None], Callable[[int], None]]:
        """``measure(k)`` (the sensors of *x* through the rig into *y*) and ``actuate(k)``
        (the torque that acts for *u_app*, within the limits *lim* (low, high per input),
        into *u_act*): a rig's effects around a controller written in Python, the same
        as the compiled loop's (the arrays kept by reference, their addresses taken once)."""
        for arr, dtype, what in ((x, np.float64, "x"), (rng, np.uint64, "rng"),
                                 (y, np.float64, "y"), (u_app, np.float64, "u_app"),
                                 (u_act, np.float64, "u_act"), (lim, np.float64, "lim"),
                                 (rig_s, np.float64, "rig_s")):
            self._out(arr, dtype, what)
        lv = np.asarray(lv, dtype=float)
        values = dict(c_idx=c_idx, ny=len(c_idx), lv=lv, nlv=lv.shape[0] if lv.ndim == 2 else 0,
                      op=op, fopts=fopts, rig_i=rig_i, rig_f=rig_f)
        args, keep = self._arrays(values)
        pargs = ctypes.byref(args)
        measure_fn, actuate_fn = self.lib.eq_rig_measure_one, self.lib.eq_rig_actuate_one
        px, prng, py, ps = _ptr(x), _ptr(rng), _ptr(y), _ptr(rig_s)
        pu, pa, pl = _ptr(u_app), _ptr(u_act), _ptr(lim)
        held = (args, keep, x, rng, y, rig_s, u_app, u_act, lim)

        def measure(k: int, _held: object = held) -> None:
            measure_fn(pargs, k, px, prng, py, ps)

        def actuate(k: int, _held: object = held) -> None:
            actuate_fn(pargs, k, pu, pa, pl, prng, ps)

        return measure, actuate

    def scratch(self, p_len: int, ny: int, nw: int) -> np.ndarray:
        width = int(self.lib.eq_scratch_width(p_len, ny, nw))
        return np.zeros((int(self.lib.eq_scratch_rows()), width))

    def advancer(self, *, x: np.ndarray, u_app: np.ndarray, op: np.ndarray,
                 p_sets: np.ndarray, p_switch: np.ndarray, lin_s: np.ndarray | None,
                 region: np.ndarray, kicks: np.ndarray, kick_value: np.ndarray,
                 pulses: np.ndarray, pulse_value: np.ndarray, lw: np.ndarray, rng: np.ndarray,
                 iopts: np.ndarray, fopts: np.ndarray, status: np.ndarray,
                 scr: np.ndarray, rig_i: np.ndarray | None = None,
                 gforce: np.ndarray | None = None) -> Callable[[int], bool]:
        """``advance(k)``: the physics steps after sample *k* with the input in *u_app* held
        (True if the state left its region; a rig's generalized forces *gforce* acting). The
        arrays are kept by reference and their addresses taken once: write the input into
        *u_app* before each call."""
        for arr, dtype, what in ((x, np.float64, "x"), (u_app, np.float64, "u_app"),
                                 (rng, np.uint64, "rng"), (status, np.int64, "status"),
                                 (scr, np.float64, "the scratch")):
            self._out(arr, dtype, what)
        lw = np.asarray(lw, dtype=float)
        p_sets = np.asarray(p_sets, dtype=float)
        values = dict(iopts=iopts, fopts=fopts, x=x, op=op, lw=lw,
                      nw=(lw.shape[1] if lw.ndim == 2 else 0), p_sets=p_sets,
                      n_sets=p_sets.shape[0], p_len=p_sets.shape[1], p_switch=p_switch,
                      lin_s=lin_s, region=region, kicks=kicks, n_kicks=len(kicks),
                      kick_value=kick_value, pulses=pulses, n_pulses=len(pulses),
                      pulse_value=pulse_value, rng=rng, status=status, ny=0, nz=0)
        values.update(self._rig(rig_i, None, gforce))
        args, keep = self._arrays(values)
        fn = self.lib.eq_advance_one
        pargs, u, sc = ctypes.byref(args), _ptr(u_app), _ptr(scr)
        held = (args, keep, u_app, scr)

        def advance(k: int, _held: object = held) -> bool:  # the arrays live as long as it
            return bool(fn(pargs, k, u, sc))

        return advance

    def plant(self, *, x: np.ndarray, p: np.ndarray, rate: float, n_sub: int,
              lw: np.ndarray, outputs: np.ndarray, lv: np.ndarray,
              rng: np.ndarray, integrator: str = integrators.DEFAULT, rig: Rig | None = None,
              op: np.ndarray | None = None) -> PlantSteps:
        """The plant alone, sample by sample, as ``simulate`` advances it around a controller
        written in Python, through *rig*'s effects if given: see :class:`PlantSteps`."""
        from equilibrist.sim.steps import PlantSteps

        return PlantSteps(self, x=x, p=p, rate=rate, n_sub=n_sub, lw=lw, outputs=outputs, lv=lv,
                          rng=rng, integrator=integrator, rig=rig, op=op)

    def rk4_steps(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, h: float,
                  n_steps: int) -> None:
        self._out(x, np.float64, "x")
        u = np.ascontiguousarray(u, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        self.lib.eq_rk4_steps(_ptr(x), _ptr(u), _ptr(p), float(h), int(n_steps))

    def normals(self, rng: np.ndarray, out: np.ndarray) -> None:
        self._out(rng, np.uint64, "rng")
        self._out(out, np.float64, "out")
        self.lib.eq_normals_into(_ptr(rng), _ptr(out), len(out))

    def f(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        self._out(out, np.float64, "out")
        x, u, p = (np.ascontiguousarray(a, dtype=float) for a in (x, u, p))
        self.lib.eq_f_one(_ptr(x), _ptr(u), _ptr(p), _ptr(out))


    # -- the identification's integrator (equilibrist.ident.kernel) ---------------------------
    def shoot_many(self, P: np.ndarray, XS: np.ndarray, bounds: np.ndarray, t: np.ndarray,
                   u: np.ndarray, n_sub: np.ndarray, c_idx: np.ndarray, yhat: np.ndarray,
                   xend: np.ndarray, *, integrator: str = integrators.DEFAULT,
                   rtol: float = integrators.RTOL, atol: float = integrators.ATOL) -> None:
        """C-contiguous arrays of the right dtypes (see ``shoot.c``); the steps of
        *integrator* (a name of :mod:`equilibrist.sim.integrators`' table)."""
        if P.shape[0] == 0:
            return
        self.lib.eq_shoot_many(integrators.number(integrator), float(rtol), float(atol),
                               _ptr(P), P.shape[0], P.shape[1], _ptr(XS), _ptr(bounds),
                               len(bounds) - 1, _ptr(t), len(t), _ptr(u), _ptr(n_sub),
                               _ptr(c_idx), len(c_idx), _ptr(yhat), _ptr(xend))

    def innovations(self, p: np.ndarray, x0: np.ndarray, t: np.ndarray, u: np.ndarray,
                    n_sub: np.ndarray, c_idx: np.ndarray, gain: np.ndarray, y: np.ndarray,
                    off: np.ndarray, e: np.ndarray, *, integrator: str = integrators.DEFAULT,
                    rtol: float = integrators.RTOL, atol: float = integrators.ATOL) -> None:
        """C-contiguous arrays of the right dtypes (see ``shoot.c``); the steps of
        *integrator*."""
        self.lib.eq_innovations(integrators.number(integrator), float(rtol), float(atol),
                                _ptr(p), _ptr(x0), _ptr(t), len(t), _ptr(u), _ptr(n_sub),
                                _ptr(c_idx), len(c_idx), _ptr(gain), _ptr(y), _ptr(off),
                                _ptr(e))


_CacheKey = tuple[Path, bytes | tuple[int, ...] | None, str | None, bool, str]
_CORES: dict[_CacheKey, NativeCore] = {}


def _cache_key(system: System, key: bytes | tuple[int, ...] | None,
               controller: NonlinearController | None, lanes: bool) -> _CacheKey:
    """A loaded core's key: a core loaded before an integrator was registered lacks it."""
    source = None if controller is None else controller.source + repr(controller.has_estimate)
    return (system.compiled.module_path, key if controller is None else None, source, lanes,
            integrators.digest())


def loaded(system: System, key: bytes | tuple[int, ...] | None = None,
           controller: NonlinearController | None = None) -> bool:
    """Whether :func:`load_core` of these (without lanes) has been called in this process."""
    return _cache_key(system, key, controller, False) in _CORES


def load_core(system: System, key: bytes | tuple[int, ...] | None = None,
              controller: NonlinearController | None = None, *, lanes: bool = False) -> NativeCore:
    """The compiled core of *system* for a linear controller made for *key*, or for the
    nonlinear *controller* (built once; raises :class:`~equilibrist.native.pyc.TranslationError`
    when the controller's source uses what the C translation does not know). *lanes*: the
    system's own core with its environment stepped in lanes (the vector environment's)."""
    cache_key = _cache_key(system, key, controller, lanes)
    core = _CORES.get(cache_key)
    if core is None:
        try:
            core = NativeCore(system, key, controller, lanes=lanes)
        except build.BuildError:
            if not lanes:
                raise
            # A compiler that does not know x86-64-v4 (GCC before 11): one copy at a time,
            # the same bits (the core says so: lanes == 1).
            core = load_core(system, key, controller)
        _CORES[cache_key] = core
    return core


__all__ = ["NativeCore", "load_core", "loaded"]

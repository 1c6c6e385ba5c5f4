"""The core's integrators, defined once: each one's name, C step, help, order and needs.

Every consumer steps through this table: ``simulate`` and ``batch`` (the
``integrator`` argument), the environments (their ``integrator`` option),
identification's multiple shooting, the playground's plant, and the command
line's ``--integrator`` choices and help. The compiled core reads it too:
:func:`c_source` writes the ``EQ_INT_<NAME>`` numbers' dispatch
(``eq_step``, ``eq_step_free``, ``eq_step_begin``, ``eq_int_lanes``) that
``native/core.c``, ``env.c`` and ``shoot.c`` call, and the named rows of each
integrator's work space (``EQ_<NAME>_<ROW>``). The built-in integrators'
steps are C in ``native/integrators.c``; :func:`register` adds one whose C
comes with it (every core made afterwards holds it), so adding an
integrator is one place.

A step's C signature (``eq_step_ctx``: ``integrators.c``)::

    int step(double *x, const double *u, const double *p, const double *w, int64_t nw,
             double h, const eq_step_ctx *c)

advances ``x`` in place over ``h`` with the input ``u`` and the parameters
``p`` held and the process noise ``w`` (``nw > 0``: drawn for this step;
``nw == 0``: zeros); ``c->work`` holds the integrator's rows (``rows``) of
``c->width`` doubles each (at least the state's size), ``c->rtol`` and
``c->atol`` the run's tolerances, ``c->op`` and ``c->lin`` a linear plant's
affine model. It returns 1, or 0 when it failed (the run then falls with
"integrator failed").
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class Integrator:
    """One integrator of the core.

    Attributes
    ----------
    name:
        What ``simulate(integrator=...)``, the environments' option and
        ``--integrator`` take (its C number is ``EQ_INT_<NAME>``).
    help:
        One line for the command line's help.
    order:
        Its global order of accuracy (the error of a fixed step ``h`` over a fixed
        time shrinks as ``h ** order``); an adaptive integrator's is its method's.
    fixed_step:
        True: one step of the physics step ``h``; False: its own steps within each
        ``h`` (to the run's tolerances), so a period is one ``h`` by default.
    step:
        The C function of one step (the signature in this module's docstring).
    rows:
        The names of its work rows (``c->work``), written ``EQ_<NAME>_<ROW>`` for its C.
    free:
        The C function of its step without noise, ``void free(double *x, const double *u,
        const double *p, double h, const eq_step_ctx *c)``; empty: *step* with zero noise.
    begin:
        The C function called at the start of every control period, ``void begin(double
        h, const eq_step_ctx *c)`` (an adaptive integrator's first step size); empty: none.
    source:
        The C that defines *step* (and *free*, *begin*); empty for the built-in ones, whose C
        is ``native/integrators.c``.
    lanes:
        Whether the vector environment's lanes (``native/lanes.py``, ``env.c``'s
        ``eqv_rk4``) step it eight copies at a time; the others' copies are stepped one
        at a time, the same bits.
    selectable:
        False for a step that a plant chooses rather than the user (``linear``: the
        linear plant's exact step, ``plant="linear"``).
    """

    name: str
    help: str
    order: int
    fixed_step: bool
    step: str
    rows: tuple[str, ...]
    free: str = ""
    begin: str = ""
    source: str = ""
    lanes: bool = False
    selectable: bool = True

    def row_constants(self) -> dict[str, int]:
        """Its work rows as source constants (``_ADAPTIVE_H_NEXT = 9``: ``EQ_ADAPTIVE_H_NEXT``)."""
        return {f"_{self.name.upper()}_{row.upper()}": k for k, row in enumerate(self.rows)}


#: The default of every consumer.
DEFAULT = "rk4"
#: The default relative and absolute tolerances of an adaptive integrator.
RTOL = 1e-8
ATOL = 1e-10

_BUILT_IN = (
    Integrator(
        name="rk4", order=4, fixed_step=True, step="eq_rk4_step_ctx", free="eq_rk4_free_ctx",
        rows=("k1", "k2", "k3", "k4", "xt"), lanes=True,
        help="classical Runge-Kutta, fixed steps of --physics-step (the default)"),
    Integrator(
        name="adaptive", order=5, fixed_step=False, step="eq_dopri_step",
        begin="eq_dopri_begin",
        rows=("k1", "k2", "k3", "k4", "k5", "k6", "k7", "yt", "yn", "h_next"),
        help="Dormand-Prince 5(4), its own steps within each period to tolerances (rtol 1e-8, "
             "atol 1e-10 by default)"),
    Integrator(
        name="linear", order=0, fixed_step=True, step="eq_linear_step", rows=("dx",),
        selectable=False,
        help="the exact step of the linearized plant (chosen by --plant linear)"),
)

_TABLE: dict[str, Integrator] = {i.name: i for i in _BUILT_IN}
_DIGEST: list[str] = []  # digest() of the table as it is (emptied when it changes)


def table() -> tuple[Integrator, ...]:
    """Every integrator, in the order of their C numbers."""
    return tuple(_TABLE.values())


def names() -> tuple[str, ...]:
    """The integrators a user may choose (the command line's choices)."""
    return tuple(i.name for i in _TABLE.values() if i.selectable)


def get(name: str) -> Integrator:
    """The integrator called *name* (KeyError if none is)."""
    return _TABLE[name]


def number(name: str) -> int:
    """The C number of the integrator called *name* (``EQ_INT_<NAME>``)."""
    return list(_TABLE).index(name)


def register(integrator: Integrator) -> None:
    """Add *integrator* to the table: every core made afterwards holds its C, and every
    consumer offers it. Its name must be new and a C identifier."""
    if integrator.name in _TABLE:
        raise ValueError(f"an integrator {integrator.name!r} exists already")
    if not integrator.name.isidentifier() or not integrator.name.isascii():
        raise ValueError(f"integrator name {integrator.name!r}: expected a C identifier")
    if integrator.lanes:
        raise ValueError("the lanes step RK4 only (env.c's eqv_rk4): register with lanes=False")
    if not integrator.source:
        raise ValueError(f"integrator {integrator.name!r}: give the C of its step (source=...)")
    _TABLE[integrator.name] = integrator
    _DIGEST.clear()


def unregister(name: str) -> None:
    """Remove an integrator added by :func:`register` (the built-in ones stay)."""
    if any(i.name == name for i in _BUILT_IN):
        raise ValueError(f"{name!r} is built in")
    _TABLE.pop(name, None)
    _DIGEST.clear()


def work_rows() -> int:
    """The rows of the largest integrator's work space."""
    return max(len(i.rows) for i in _TABLE.values())


def constants() -> dict[str, int]:
    """The integrators' numbers (``_INT_RK4 = 0``...), their work rows
    (``_ADAPTIVE_H_NEXT = 9``...) and the work space's rows (``_STEP_ROWS``)."""
    out = {f"_INT_{i.name.upper()}": k for k, i in enumerate(_TABLE.values())}
    for i in _TABLE.values():
        out.update(i.row_constants())
    out["_STEP_ROWS"] = work_rows()
    return out


def digest() -> str:
    """What the table adds to a core (the registered integrators' C): part of its cache key."""
    if not _DIGEST:
        h = hashlib.sha256()
        for i in _TABLE.values():
            h.update(repr(i).encode())
        _DIGEST.append(h.hexdigest())
    return _DIGEST[0]


_ARGS = "double *x, const double *u, const double *p"


def c_source() -> str:
    """The registered integrators' C and the dispatch over the table, for the core after
    ``integrators.c``: ``eq_step``, ``eq_step_free``, ``eq_step_begin``, ``eq_int_lanes``."""
    parts = ["\n/* ---- the integrators' table (equilibrist.sim.integrators), generated ---- */\n"]
    parts += [f"/* integrator {i.name} */\n{i.source}\n" for i in _TABLE.values() if i.source]
    steps, frees, begins = [], [], []
    for i in _TABLE.values():
        case = f"    case EQ_INT_{i.name.upper()}:"
        steps.append(f"{case} return {i.step}(x, u, p, w, nw, h, c);\n")
        if i.free:
            frees.append(f"{case} {i.free}(x, u, p, h, c); return 1;\n")
        else:
            frees.append(f"{case} return {i.step}(x, u, p, zero, 0, h, c);\n")
        if i.begin:
            begins.append(f"{case} {i.begin}(h, c); return;\n")
    lanes = " || ".join(f"integrator == EQ_INT_{i.name.upper()}"
                        for i in _TABLE.values() if i.lanes) or "0"
    return "".join(parts) + (
        "\n/* One step of integrator number `integrator` (EQ_INT_*): 1, or 0 if it failed. */\n"
        f"static inline int eq_step(int64_t integrator, {_ARGS}, const double *w, int64_t nw,\n"
        "                          double h, const eq_step_ctx *c)\n{\n"
        f"    switch (integrator) {{\n{''.join(steps)}    }}\n    return 0;\n}}\n"
        "\n/* The same without noise (identification's shooting): 1, or 0 if it failed. */\n"
        f"static inline int eq_step_free(int64_t integrator, {_ARGS}, double h,\n"
        "                               const eq_step_ctx *c)\n{\n"
        "    double zero[EQ_N];\n    int i;\n    for (i = 0; i < EQ_N; i++) zero[i] = 0.0;\n"
        f"    switch (integrator) {{\n{''.join(frees)}    }}\n    (void)zero;\n    return 0;\n}}\n"
        "\n/* At the start of a control period of steps of h. */\n"
        "static inline void eq_step_begin(int64_t integrator, double h, const eq_step_ctx *c)\n"
        f"{{\n    switch (integrator) {{\n{''.join(begins)}    }}\n"
        "    (void)h;\n    (void)c;\n}\n"
        "\n/* Whether the vector environment's lanes step this integrator (env.c's eqv_rk4). */\n"
        f"static inline int eq_int_lanes(int64_t integrator) {{ return {lanes}; }}\n"
    )


def check(name: object, *, what: str = "integrator ") -> str | None:
    """What is wrong with *name* as a user's choice of integrator (the message begins with
    *what*), or None."""
    if isinstance(name, str) and name in _TABLE and _TABLE[name].selectable:
        return None
    return f"{what}{name!r}: expected one of {', '.join(names())}"


def help_text() -> str:
    """The command line's help of ``--integrator``: each choice with its line."""
    return "; ".join(f"{i.name}: {i.help}" for i in _TABLE.values() if i.selectable)


__all__ = ["ATOL", "DEFAULT", "RTOL", "Integrator", "c_source", "check", "constants", "digest", "get",
           "help_text", "names", "number", "register", "table", "unregister", "work_rows"]

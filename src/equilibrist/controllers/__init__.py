"""The project's controller kinds, one module each (see :mod:`equilibrist.control.kinds`).

Every module here defines ``KIND``, a :class:`~equilibrist.control.kinds.ControllerKind`;
the registry lists the package, so a new kind is a new module and nothing else.
A kind's module imports no numerics at import time (the command line lists the
kinds to build its parser): its ``build`` imports what it needs.
"""

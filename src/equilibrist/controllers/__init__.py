"""The project's controller kinds, one module each (see :mod:`equilibrist.controllers.kinds`).

Every module here defines ``KIND``, a :class:`~equilibrist.controllers.kinds.ControllerKind`;
the registry lists the package, so a new kind is a new module and nothing else.
A kind's module imports no numerics at import time (the command line lists the
kinds to build its parser): its ``build`` imports what it needs.
"""

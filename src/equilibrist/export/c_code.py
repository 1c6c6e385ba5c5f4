"""The text of the exported C99 library, its examples, test program and Makefile.

Every function here is pure: it takes a :class:`~equilibrist.export.data.ControllerData`
(and, for the test vectors, a recorded run) and returns the text of one
file. Writing them is :mod:`equilibrist.export.writer`'s job.

The step function runs the linear controller's library translated from its Python source
(:func:`equilibrist.export.linear_c.linear_c`, the simulation core's own translation of
``LINEAR_SOURCE`` for the controller's sizes) on the design's packed form: in double
precision the C controller and the simulated one agree to the last bit.

The functions live in :mod:`equilibrist.export._c_library` (the header and the
source), :mod:`equilibrist.export._c_programs` (the test vectors and program, the
examples, the Makefile and README) and :mod:`equilibrist.export._c_text` (the
literals and names they share, :class:`Vectors`); they are imported from here.
"""

from __future__ import annotations

from equilibrist.export._c_library import header, source
from equilibrist.export._c_programs import (
    arduino_sketch,
    desktop_example,
    makefile,
    readme,
    test_program,
    vectors_header,
)
from equilibrist.export._c_text import Vectors, literal

__all__ = [
    "Vectors",
    "arduino_sketch",
    "desktop_example",
    "header",
    "literal",
    "makefile",
    "readme",
    "source",
    "test_program",
    "vectors_header",
]

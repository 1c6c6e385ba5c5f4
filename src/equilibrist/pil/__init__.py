"""Processor in the loop: the exported controller built for a microcontroller and run in its emulator.

The export's hardware-in-the-loop sketch (:mod:`equilibrist.native.firmware`)
is compiled with the chip's own toolchain (:mod:`equilibrist.pil.firmware`)
and run in an emulator whose UART is a pseudo-terminal
(:mod:`equilibrist.pil.emulator`); the host's side of the link and the
lockstep are :mod:`equilibrist.hil`'s. :mod:`equilibrist.pil.run` adds what
the chip tells: cycles per step against the period's budget, flash, static
RAM, the stack's high-water mark, and the run's difference from ``simulate``.
``docs/pil.md`` is the reference.
"""

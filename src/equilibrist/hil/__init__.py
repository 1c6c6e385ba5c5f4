"""Hardware in the loop: the exported controller on a device, closed over a serial link.

The simulator plays the plant in real time (or in lockstep), the device runs
the exported C (every export adds the protocol, :mod:`equilibrist.native.firmware`,
and ``make hil-host`` builds the same C as a host program), and the two talk
over the link the rig will use (:mod:`equilibrist.hil.protocol`,
``docs/hil.md``). Needs pyserial: ``pip install 'equilibrist[hil]'``.
"""

"""C: Python definitions translated to C and compiled once, cached by content (the core), and
every C file that ships (the controllers' libraries, their tests, the HIL firmware)."""

"""The generated C core: Python definitions translated to C, compiled once, cached by content."""

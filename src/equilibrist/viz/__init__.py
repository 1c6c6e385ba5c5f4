"""Show it balance: plots, pole maps, drawings and animations of every system.

Modules
-------
scenes
    One drawing per system of the catalogue, built from a state vector and
    the system's parameters only (never from its dynamics).
frames
    A figure that renders a scene with a time stamp and the input gauges,
    frame by frame, to RGB arrays or a PNG.
animation
    Animations from arrays or from a simulation result: GIF (pure Python)
    and MP4 where ffmpeg is installed.
plots
    Time responses, comparisons, Monte-Carlo fans, regions of attraction
    and pole maps, saved as PNG or SVG.
runs
    The read-only view of simulation results that the plots and animations
    share.
report
    The ``index.html`` of a report folder: one offline page with the
    pictures, the facts of each run and the equations of motion.
tour
    The main job (``equilibrist demo``): design, simulate, plot and animate
    every system of the catalogue and write the report folder.
cli_hooks
    ``--plot`` / ``--animate`` options for commands that produce a result.

Nothing here imports matplotlib at import time; each function imports it
when it draws.
"""

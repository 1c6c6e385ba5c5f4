"""Applications: what the project shows with its libraries, above every one of them.

The demo's tour and report (:mod:`equilibrist.apps.tour`), the MPC's and the
swing-up's demonstrations (:mod:`~equilibrist.apps.mpc_demo`,
:mod:`~equilibrist.apps.swingup_demo`) and the planned swing-up
(:mod:`~equilibrist.apps.planned_demo`) use the systems, control, simulation
and drawing (:mod:`equilibrist.viz`) libraries; no library imports them. The
other applications have their own packages: the commands (``cli``), the
playground (``web``), studies (``study``), the environments (``envs``).
"""

"""Show it balance: plots, pole maps, drawings and animations of every system, and the
report's page.

Drawings are built from states and parameters only, never from the dynamics. Nothing here
imports matplotlib at import time; each function imports it when it draws.
"""

"""The catalogue: one module per system of SYSTEMS.md, registered by decorator."""

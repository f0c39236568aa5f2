"""Names the excitation package gives out, kept apart from its numerics so that the command
line can offer them without importing numpy and scipy."""

CONTROLS = ("aileron", "elevator", "rudder", "throttle")
PRESETS = ("lateral", "longitudinal", "full")

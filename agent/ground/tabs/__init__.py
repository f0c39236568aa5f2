"""The console's tabs, one widget each. Each holds what it shows as reactive state, which the
app sets from the station's events, and redraws what changed; commands go out through the
`send` it is given, which logs a command the radio could not take."""

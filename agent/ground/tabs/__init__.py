"""The console's tabs, one widget each. Each draws from the GroundStation in `show()` (called
by the app on every refresh) and sends commands through the `send` it is given, which logs a
command the radio could not take."""

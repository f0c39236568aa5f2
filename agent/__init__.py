"""suas-sysid: online near real-time system identification for small fixed-wing aircraft."""

__version__ = "0.1.0"

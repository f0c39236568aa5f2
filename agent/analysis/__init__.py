"""Offline analysis: flight records, replay and reports (the same code as onboard)."""

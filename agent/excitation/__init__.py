"""Excitation signals, flight plans and the scheduler that plays them (issue 4 completes it)."""

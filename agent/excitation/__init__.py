"""Excitation signals, flight plans and the scheduler that plays them."""

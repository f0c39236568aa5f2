"""Digi XBee-PRO 900HP in DigiMesh API mode."""

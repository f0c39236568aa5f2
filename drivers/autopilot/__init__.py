"""ArduPlane through MAVSDK."""

"""Hardware-free flight: the JSBSim plant (issue 6 adds the emulated autopilot, sensors, radios)."""

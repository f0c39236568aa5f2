"""Hardware-free flight: the JSBSim plant, the emulated ArduPlane, sensors and radios, the
scripted pilot and operator, and the validated linear truth."""

"""The magnetometer's calibration: coverage of the sphere, the fit, simulated tours."""

"""Tools that run beside hardware: C verification, I2C readout, calibration flashing."""

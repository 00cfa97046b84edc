"""Slave control: CLIK (eq. 21), variable-gain PD with gravity compensation (eq. 20)."""

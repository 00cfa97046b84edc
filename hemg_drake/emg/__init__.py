"""sEMG chain: sources, RMS envelope (eqs. 1-2), calibration, gain law (eq. 22)."""

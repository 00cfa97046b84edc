"""Teleoperation: haptic master (eq. 19), simulated operator, workspace map, force feedback."""

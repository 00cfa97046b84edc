"""Shared control: the learnt model assists the operator while they teleoperate."""

"""hemg-drake: haptic + sEMG teleoperation of a Baxter arm, with HSMM-GMR task learning.

Importing the package starts nothing (no Meshcat, no simulation); see ``hemg_drake.cli``.
"""

__version__ = "0.1.0"

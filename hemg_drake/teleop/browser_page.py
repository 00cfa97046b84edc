"""The teleop page on Meshcat: what the hand cannot feel (:class:`TeleopPage`). The Meshcat
server a take is driven from is a loopback ``Visualization``
(:mod:`hemg_drake.diagrams.visualization`)."""

import math

import numpy as np
from pydrake.geometry import Cylinder, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix

# Read-only sliders that show what the hand cannot feel.
# (Meshcat shows about 14 characters of a control's name.)
SHOW_FORCE, SHOW_GAIN = "force f_WE (N)", "gain K"
SHOW_TIME, SHOW_RECORDING = "time (s)", "recording"
MAX_SHOWN_FORCE = 60.0


class TeleopPage:
    """What the hand cannot feel, on the Meshcat page: the slave's force as an arrow at the
    tool (1 cm per newton) and a bar, the gain K, the time, whether a take is recording,
    and the stylus target (a small sphere, mapped to the slave's side).

    The bar, K, time and recording flag are read-only sliders (Meshcat's controls have no
    text field); :meth:`update` sets them with ``SetSliderValue``.
    """

    PATH = "/teleop"
    ARROW_SCALE = 0.01  # m per N

    def __init__(self, meshcat, *, k_min, k_max):
        self.meshcat = meshcat
        existing = set(meshcat.GetSliderNames())
        for name, high, step, value in ((SHOW_FORCE, MAX_SHOWN_FORCE, 0.1, 0.0),
                                        (SHOW_GAIN, math.ceil(k_max), 0.1, k_min),
                                        (SHOW_TIME, 3600.0, 0.01, 0.0),
                                        (SHOW_RECORDING, 1.0, 1.0, 0.0)):  # fmt: skip
            if name in existing:
                meshcat.SetSliderValue(name, value)
            else:
                meshcat.AddSlider(name, 0.0, high, step, value)
        orange = Rgba(1.0, 0.5, 0.0, 1.0)
        # The arrow points along its frame's +z; the shaft (1 m, scaled) and the head are
        # separate paths so scaling the shaft does not stretch the head.
        meshcat.SetObject(f"{self.PATH}/force/shaft/geometry", Cylinder(0.004, 1.0), orange)
        meshcat.SetTransform(f"{self.PATH}/force/shaft/geometry", RigidTransform([0, 0, 0.5]))
        meshcat.SetObject(f"{self.PATH}/force/head", MeshcatCone(0.02, 0.01, 0.01), orange)
        meshcat.SetObject(f"{self.PATH}/target", Sphere(0.012), Rgba(0.1, 0.6, 1.0, 0.7))
        meshcat.SetProperty(f"{self.PATH}/force", "visible", False)
        meshcat.SetProperty("/Axes", "visible", False)  # the world axes hide the arm's base
        self.updates = 0

    def update(self, t, p_WE, f_WE, gain, recording, p_WT=None):
        m = self.meshcat
        f = np.asarray(f_WE, dtype=float)
        magnitude = float(np.linalg.norm(f))
        m.SetSliderValue(SHOW_FORCE, min(magnitude, MAX_SHOWN_FORCE))
        m.SetSliderValue(SHOW_GAIN, float(gain))
        m.SetSliderValue(SHOW_TIME, float(t))
        m.SetSliderValue(SHOW_RECORDING, 1.0 if recording else 0.0)
        length = self.ARROW_SCALE * magnitude
        visible = length > 1e-3
        m.SetProperty(f"{self.PATH}/force", "visible", visible)
        if visible:
            R = _rotation_z_to(f / magnitude)
            # The cone's apex is at its frame's origin and it opens along +z: turn it over.
            head = RigidTransform(R, p_WE) @ RigidTransform(
                RotationMatrix.MakeXRotation(math.pi), [0, 0, length + 0.02]
            )
            m.SetTransform(f"{self.PATH}/force/shaft", RigidTransform(R, p_WE))
            m.SetProperty(f"{self.PATH}/force/shaft", "scale", [1.0, 1.0, length])
            m.SetTransform(f"{self.PATH}/force/head", head)
        if p_WT is not None:
            m.SetTransform(f"{self.PATH}/target", RigidTransform(np.asarray(p_WT, float)))
        self.updates += 1


def _rotation_z_to(direction):
    """A rotation taking +z to the unit vector ``direction``."""
    z = np.asarray(direction, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return RotationMatrix(np.column_stack([x, y, z]))


"""Physical master devices: the interface, its Drake adapter, and the Touch X.

A master device is anything that reports where the operator's stylus tip S is and
accepts a force to render on it (``MasterDevice``: position in m, force in N, both in the
master frame M of ``hemg_drake/teleop/mapping.py``). ``DeviceMaster`` wraps one as a Drake
system with the ports that the ``HapticMaster``'s consumers read (``p_MS``, ``v_MS``,
``state``; ``motor_force`` in), so a real device replaces the simulated master in the
demonstration diagram without rewiring: the operator's hand is then the real one.
``TouchXDevice`` reads a 3D Systems Touch X (or any OpenHaptics device) through the
optional ``pyOpenHaptics`` package (extra ``hemg-drake[touchx]``; it needs the vendor's
OpenHaptics SDK). Running with a real device: ``docs/devices.md``.
"""

import abc
import math
import threading
import time

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import DiscreteDerivative, FirstOrderLowPassFilter, Multiplexer

from hemg_drake._validate import as_scalar, as_vector
from hemg_drake.teleop.config import MasterConfig
from hemg_drake.teleop.master import TOUCH_X_PEAK_FORCE, saturate_norm

# OpenHaptics reports positions in millimetres.
MM = 1e-3
# The device's servo loop renders a commanded force this long at most before it falls back
# to zero: a simulation that stopped or hangs must not leave a force in the operator's hand.
FORCE_TIMEOUT = 0.05
_INSTALL_HINT = "install the optional extra: pip install 'hemg-drake[touchx]'"


class MasterDevice(abc.ABC):
    """What a master device gives and takes; implement it to plug a device in.

    Units and frame: metres, newtons, the master frame M (origin at the centre of the
    device's workspace; x to the operator's right, y up, z towards the operator).
    """

    @abc.abstractmethod
    def position(self):
        """The stylus tip now, p_MS (m, M), shape (3,)."""

    @abc.abstractmethod
    def apply_force(self, f_MS):
        """Render the force ``f_MS`` (N, M) on the stylus until the next call."""

    def velocity(self):
        """The tip's velocity v_MS (m/s, M), or None to let ``DeviceMaster`` differentiate."""
        return None

    def close(self):
        """Release the device (zero force first)."""


class _DeviceSampler(LeafSystem):
    """The device's sampler inside :class:`DeviceMaster`: sends ``motor_force``, reads the tip.

    .. pydrake_system::

        name: _DeviceSampler
        input_ports:
        - motor_force
        output_ports:
        - p_MS
        - v_MS (the device's own velocity, when it gives one)

    At initialisation it reads the device; then every ``period`` (offset 0) it sends
    ``motor_force`` (N, M) saturated in norm at ``max_force`` to the device and reads it
    again: ``device.position()`` (m, M) and, for a device with its own velocity,
    ``device.velocity()`` (m/s), into its discrete state. Not
    scalar-convertible: it drives one physical device (a clone would drive it twice).
    """

    def __init__(self, device, period, p_MS_initial, max_force, with_velocity):
        LeafSystem.__init__(self)
        self._device = device
        self._max_force = max_force
        self._with_velocity = with_velocity
        self._motor_force_input = self.DeclareVectorInputPort("motor_force", 3)
        self._p_index = self.DeclareDiscreteState(p_MS_initial)
        self.DeclareStateOutputPort("p_MS", self._p_index)
        if with_velocity:
            self._v_index = self.DeclareDiscreteState(np.zeros(3))
            self.DeclareStateOutputPort("v_MS", self._v_index)
        self.DeclareInitializationDiscreteUpdateEvent(self._read)
        self.DeclarePeriodicDiscreteUpdateEvent(
            period_sec=period, offset_sec=0.0, update=self._update
        )

    @staticmethod
    def _finite(name, values):
        values = np.asarray(values, dtype=float)
        if values.shape != (3,) or not np.all(np.isfinite(values)):
            raise ValueError(
                f"DeviceMaster: device.{name}() must return 3 finite values, got {values!r}"
            )
        return values

    def _update(self, context, discrete_state):
        force = self._motor_force_input.Eval(context).tolist()
        if not all(math.isfinite(f) for f in force):
            raise ValueError(f"DeviceMaster: motor_force must be finite, got {force}")
        self._device.apply_force(saturate_norm(force, self._max_force))
        self._read(context, discrete_state)

    def _read(self, context, discrete_state):
        discrete_state.set_value(self._p_index, self._finite("position", self._device.position()))
        if self._with_velocity:
            velocity = self._finite("velocity", self._device.velocity())
            discrete_state.set_value(self._v_index, velocity)


def _has_own_velocity(device):
    """Whether ``device`` overrides :meth:`MasterDevice.velocity` (or, duck-typed, has one)."""
    method = getattr(type(device), "velocity", None)
    return callable(method) and method is not MasterDevice.velocity


class DeviceMaster(Diagram):
    """A physical master device in a diagram, in place of the ``HapticMaster``.

    .. pydrake_system::

        name: DeviceMaster
        input_ports:
        - motor_force
        output_ports:
        - state
        - p_MS
        - v_MS

    Eq. 19's master side is the device itself: this system only samples it. It reads the
    tip position ``p_MS`` (3, m, M) at initialisation, and at each periodic discrete
    update (every ``period``, offset 0) it sends ``motor_force`` (3, N, M; saturated in
    norm at ``max_force``) to the device, then reads the tip again. ``v_MS`` (3, m/s) is the device's own velocity when its class
    overrides :meth:`MasterDevice.velocity`, else Drake's ``DiscreteDerivative`` of the
    sampled positions (zero for its first two samples) through Drake's continuous
    ``FirstOrderLowPassFilter`` of time constant ``velocity_time_constant`` (0: the raw
    difference, no filter). ``state`` is [p_MS; v_MS] (a ``Multiplexer``). The outputs
    depend on state only, as the ``HapticMaster``'s do, so the force feedback loop has no
    algebraic loop. Before initialisation ``p_MS`` is ``p_MS_initial``, ``v_MS`` zero. A
    non-finite force or position raises ValueError (and the force is not sent). The
    filter's state is continuous: the simulator integrates it between samples.

    Run the simulator at real-time rate (``set_target_realtime_rate(1)``).

    Parameters
    ----------
    device : MasterDevice (or any object with ``position()`` and ``apply_force(f)``)
    period : float
        Sampling period in s (the Touch X's servo loop runs at 1 kHz).
    p_MS_initial : array-like, shape (3,)
    max_force : float
        Norm limit of the force sent (N; Touch X: 7.9).
    velocity_time_constant : float
        Low-pass time constant of the differentiated velocity (s); 0 for none.
    """

    def __init__(
        self,
        *,
        device,
        period=MasterConfig.period,
        p_MS_initial=(0.0, 0.0, 0.0),
        max_force=TOUCH_X_PEAK_FORCE,
        velocity_time_constant=5e-3,
    ):
        Diagram.__init__(self)
        for name in ("position", "apply_force"):
            if not callable(getattr(device, name, None)):
                raise ValueError(f"device must have a {name}() method (see MasterDevice)")
        period = as_scalar("period", period)
        tau = as_scalar("velocity_time_constant", velocity_time_constant, strict=False)
        with_velocity = _has_own_velocity(device)
        builder = DiagramBuilder()
        sampler = builder.AddNamedSystem(
            "sampler",
            _DeviceSampler(
                device, period, as_vector("p_MS_initial", p_MS_initial, 3),
                as_scalar("max_force", max_force), with_velocity,
            ),
        )  # fmt: skip
        p_MS = sampler.GetOutputPort("p_MS")
        if with_velocity:
            v_MS = sampler.GetOutputPort("v_MS")
        else:
            derivative = builder.AddNamedSystem("derivative", DiscreteDerivative(3, period))
            builder.Connect(p_MS, derivative.get_input_port())
            v_MS = derivative.get_output_port()
            if tau > 0:
                low_pass = builder.AddNamedSystem("low_pass", FirstOrderLowPassFilter(tau, 3))
                builder.Connect(v_MS, low_pass.get_input_port())
                v_MS = low_pass.get_output_port()
        join = builder.AddNamedSystem("join", Multiplexer([3, 3]))
        builder.Connect(p_MS, join.get_input_port(0))
        builder.Connect(v_MS, join.get_input_port(1))
        self._motor_force_input = builder.ExportInput(
            sampler.GetInputPort("motor_force"), "motor_force"
        )
        builder.ExportOutput(join.get_output_port(), "state")
        builder.ExportOutput(p_MS, "p_MS")
        builder.ExportOutput(v_MS, "v_MS")
        builder.BuildInto(self)

    def get_motor_force_input_port(self):
        return self.GetInputPort("motor_force")

    def get_p_MS_output_port(self):
        return self.GetOutputPort("p_MS")

    def get_v_MS_output_port(self):
        return self.GetOutputPort("v_MS")

    def get_state_output_port(self):
        return self.GetOutputPort("state")


def _import_pyopenhaptics():
    try:
        import pyOpenHaptics.hd as hd
        from pyOpenHaptics.hd_callback import hd_callback
        from pyOpenHaptics.hd_device import HapticDevice
    except ImportError as error:
        raise ModuleNotFoundError(
            f"the Touch X needs the pyOpenHaptics package ({_INSTALL_HINT})"
        ) from error
    except OSError as error:  # pyOpenHaptics loads libHD when imported
        raise RuntimeError(
            f"pyOpenHaptics could not load the OpenHaptics library ({error}): install 3D "
            f"Systems' OpenHaptics SDK and the device driver (docs/devices.md)"
        ) from error
    return hd, hd_callback, HapticDevice


class TouchXDevice(MasterDevice):
    """A Touch X (or any OpenHaptics device) through ``pyOpenHaptics``.

    OpenHaptics runs a servo loop at 1 kHz in its own thread; its callback here reads the
    tip position (``hd.get_transform()``'s translation, mm, device frame D) and the
    buttons, and renders the last commanded force (``hd.set_force``, N, D). The force
    falls back to zero when no new command came for ``force_timeout`` seconds.

    Frames: D is OpenHaptics' device frame (x to the operator's right, y up, z towards
    the operator; origin where the device was calibrated, near the workspace centre),
    which has the axes of the master frame M: by default ``R_MD`` is the identity and
    ``p_MD`` zero, so p_MS = p_MD + R_MD p_DS with p_DS converted from mm to m. Forces
    go back as f_D = R_MD^T f_M, saturated in norm at ``max_force``.

    Parameters
    ----------
    device_name : str
        OpenHaptics device name ("Default Device": the one set in Touch Setup).
    p_MD : array-like, shape (3,)
        D's origin in M (m): to centre M on the box the workspace checks use.
    R_MD : array-like, shape (3, 3)
        D's axes in M (a rotation matrix), for a device mounted turned.
    max_force : float
        N (Touch X: 7.9).
    force_timeout : float
        s without a command after which the servo loop renders zero.
    answer_timeout : float
        s to wait for the first servo sample before giving up.
    clock : callable
        Monotonic time in s (tests pass a fake one).
    """

    def __init__(
        self,
        *,
        device_name="Default Device",
        p_MD=(0.0, 0.0, 0.0),
        R_MD=np.eye(3),
        max_force=TOUCH_X_PEAK_FORCE,
        force_timeout=FORCE_TIMEOUT,
        answer_timeout=2.0,
        clock=time.monotonic,
    ):
        self._p_MD = as_vector("p_MD", p_MD, 3)
        R = np.asarray(R_MD, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or not (
            np.linalg.det(R) > 0
        ):
            raise ValueError(f"R_MD must be a 3 x 3 rotation matrix, got {R_MD!r}")
        self._R_MD = R
        self._max_force = as_scalar("max_force", max_force)
        self._force_timeout = as_scalar("force_timeout", force_timeout)
        self._clock = clock
        self._lock = threading.Lock()
        self._p_DS_mm = None
        self._buttons = 0
        self._force_D = [0.0, 0.0, 0.0]
        self._force_time = -math.inf
        self._servo_count = 0
        hd, hd_callback, HapticDevice = _import_pyopenhaptics()
        self._hd = hd

        def servo():
            # OpenHaptics' servo thread, 1 kHz: keep it short, no allocation-heavy work.
            transform = hd.get_transform()
            p = [float(transform[3][0]), float(transform[3][1]), float(transform[3][2])]
            buttons = int(hd.get_buttons())
            with self._lock:
                self._p_DS_mm, self._buttons = p, buttons
                self._servo_count += 1
                fresh = self._clock() - self._force_time <= self._force_timeout
                force = self._force_D if fresh else [0.0, 0.0, 0.0]
            hd.set_force(force)

        # The ctypes callback must outlive the scheduler: keep a reference.
        self._callback = hd_callback(servo)
        self._device = HapticDevice(
            callback=self._callback, device_name=device_name, scheduler_type="async"
        )
        deadline = time.monotonic() + float(answer_timeout)
        while self._p_DS_mm is None:
            if time.monotonic() >= deadline:
                self._close_device()
                raise RuntimeError(
                    f"no OpenHaptics device {device_name!r} answered within "
                    f"{float(answer_timeout):g} s: check the cable, the driver and Touch "
                    f"Setup (docs/devices.md)"
                )
            time.sleep(0.001)

    @property
    def buttons(self):
        """The stylus buttons as OpenHaptics' bit mask (1: first button, 2: second)."""
        with self._lock:
            return self._buttons

    @property
    def servo_count(self):
        """Servo-loop callbacks so far (1 kHz while the device runs)."""
        with self._lock:
            return self._servo_count

    def position(self):
        with self._lock:
            p_DS = np.asarray(self._p_DS_mm, dtype=float) * MM
        return self._p_MD + self._R_MD @ p_DS

    def apply_force(self, f_MS):
        f_MS = np.asarray(f_MS, dtype=float)
        if f_MS.shape != (3,) or not np.all(np.isfinite(f_MS)):
            raise ValueError(f"f_MS must be 3 finite values (N), got {f_MS!r}")
        force_D = saturate_norm((self._R_MD.T @ f_MS).tolist(), self._max_force)
        with self._lock:
            self._force_D, self._force_time = force_D, self._clock()

    def _close_device(self):
        with self._lock:
            self._force_D, self._force_time = [0.0, 0.0, 0.0], -math.inf
        self._device.close()

    def close(self):
        """Zero the force and stop OpenHaptics' scheduler."""
        self._close_device()

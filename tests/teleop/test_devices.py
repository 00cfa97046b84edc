"""Master devices: DeviceMaster through Drake with a scripted device, and the Touch X
adapter with a fake pyOpenHaptics module (the real one needs the vendor's SDK)."""

import math
import sys
import types

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from hemg_drake.teleop.devices import DeviceMaster, MasterDevice, TouchXDevice
from hemg_drake.teleop.feedback import ForceFeedback
from hemg_drake.teleop.mapping import WorkspaceMap, WorkspaceMapping

PERIOD = 1e-3


class RampDevice(MasterDevice):
    """A tip moving at constant velocity from p0, one sample per position() call."""

    def __init__(self, p0, velocity, period=PERIOD):
        self.p0, self.velocity_ = np.asarray(p0), np.asarray(velocity)
        self.period, self.calls, self.forces = period, 0, []

    def position(self):
        p = self.p0 + self.velocity_ * self.calls * self.period
        self.calls += 1
        return p

    def apply_force(self, f_MS):
        self.forces.append(list(f_MS))


def _run(device, n_steps, force=(0.0, 0.0, 0.0), **kwargs):
    builder = DiagramBuilder()
    master = builder.AddSystem(DeviceMaster(device=device, **kwargs))
    source = builder.AddSystem(ConstantVectorSource(np.asarray(force, dtype=float)))
    builder.Connect(source.get_output_port(), master.get_motor_force_input_port())
    logs = {
        name: LogVectorOutput(master.GetOutputPort(name), builder, publish_period=PERIOD)
        for name in ("p_MS", "v_MS", "state")
    }
    simulator = Simulator(builder.Build())
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)  # the filter's state
    simulator.AdvanceTo(n_steps * PERIOD - PERIOD / 2)
    context = simulator.get_context()
    # A logger at t_k sees the state before the update at t_k: shift by one sample.
    return {name: log.FindLog(context).data().T[1:] for name, log in logs.items()}


def test_positions_pass_through_and_velocity_is_the_filtered_difference():
    p0, velocity, tau = [0.01, -0.02, 0.03], np.array([0.1, 0.0, -0.05]), 4e-3
    device = RampDevice(p0, velocity)
    out = _run(device, 30, velocity_time_constant=tau)
    k = np.arange(len(out["p_MS"]))  # updates 0 .. 28 seen
    # The device is read at initialisation (p0), then once per update.
    np.testing.assert_allclose(
        out["p_MS"], p0 + np.outer((k + 1) * PERIOD, velocity), atol=1e-15
    )
    # Drake's DiscreteDerivative of the sampled positions is v from its second sample (at
    # t = T; zero before), and the continuous low-pass filter's step response from there is
    # v (1 - exp(-(t - T) / tau)); row k is read at t = (k + 1) T.
    t = (k + 1) * PERIOD
    expected = np.outer(np.where(t > PERIOD, 1.0 - np.exp(-(t - PERIOD) / tau), 0.0),
                        velocity)  # fmt: skip
    np.testing.assert_allclose(out["v_MS"], expected, rtol=1e-7, atol=1e-12)
    assert np.linalg.norm(out["v_MS"][-1] - velocity) < 0.01 * np.linalg.norm(velocity)
    np.testing.assert_allclose(out["state"], np.hstack([out["p_MS"], out["v_MS"]]))


def test_raw_difference_and_device_velocity():
    velocity = np.array([0.2, -0.1, 0.0])
    out = _run(RampDevice([0, 0, 0], velocity), 5, velocity_time_constant=0.0)
    np.testing.assert_array_equal(out["v_MS"][:1], np.zeros((1, 3)))  # suppressed at first
    np.testing.assert_allclose(out["v_MS"][2:], np.tile(velocity, (2, 1)), rtol=1e-9)

    class WithVelocity(RampDevice):
        def velocity(self):
            return [9.0, 8.0, 7.0]

    out = _run(WithVelocity([0, 0, 0], velocity), 3)
    np.testing.assert_array_equal(out["v_MS"], [[9.0, 8.0, 7.0]] * 2)


def test_force_is_sent_saturated_in_norm_keeping_its_direction():
    device = RampDevice([0, 0, 0], [0, 0, 0])
    _run(device, 3, force=(6.0, 0.0, 8.0))  # norm 10 N > 7.9 N
    np.testing.assert_allclose(device.forces[0], [6.0 * 0.79, 0.0, 8.0 * 0.79], rtol=1e-12)
    assert device.calls == len(device.forces) + 1  # read at start, then once per command


def test_bad_device_and_bad_values_are_named():
    with pytest.raises(ValueError, match=r"device must have a position\(\) method"):
        DeviceMaster(device=object())

    class NanDevice(RampDevice):
        def position(self):
            return [0.0, math.nan, 0.0]

    with pytest.raises(ValueError, match="3 finite values"):
        _run(NanDevice([0, 0, 0], [0, 0, 0]), 2)
    device = RampDevice([0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="motor_force must be finite"):
        _run(device, 2, force=(math.nan, 0.0, 0.0))
    assert device.forces == []


def test_device_master_closes_the_teleoperation_loop_like_the_haptic_master():
    # The HapticMaster's consumers (map, force feedback) connect to it unchanged.
    mapping = WorkspaceMapping(scale=2.0, p_WMo=[0.7, -0.2, 0.25])
    device = RampDevice([0.0, 0.01, 0.0], [0.0, 0.0, 0.0])
    builder = DiagramBuilder()
    master = builder.AddSystem(DeviceMaster(device=device))
    to_slave = builder.AddSystem(WorkspaceMap(mapping=mapping, period=PERIOD))
    feedback = builder.AddSystem(ForceFeedback(mapping=mapping, period=PERIOD))
    for name in ("p_MS", "v_MS"):
        builder.Connect(master.GetOutputPort(name), to_slave.GetInputPort(name))
    builder.Connect(feedback.GetOutputPort("motor_force"), master.GetInputPort("motor_force"))
    f_WE = builder.AddSystem(ConstantVectorSource(np.array([0.0, 0.0, 4.0])))
    builder.Connect(f_WE.get_output_port(), feedback.GetInputPort("f_WE"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.0025)
    context = to_slave.GetMyContextFromRoot(simulator.get_context())
    np.testing.assert_allclose(
        to_slave.GetOutputPort("p_WE_desired").Eval(context),
        mapping.master_to_slave([0.0, 0.01, 0.0]),
    )
    # +z_W is the device's up (+y_M); the force comes back divided by the scale.
    np.testing.assert_allclose(device.forces[-1], [0.0, 2.0, 0.0], atol=1e-12)


# ----------------------------------------------------------------- Touch X, fake pyOpenHaptics


class FakeOpenHaptics:
    """pyOpenHaptics' API as used (hd.get_transform/get_buttons/set_force, hd_callback,
    HapticDevice); ``tick()`` runs one servo-loop callback, as OpenHaptics' thread does."""

    def __init__(self, *, answers=True):
        self.p_mm = [0.0, 0.0, 0.0]
        self.buttons, self.forces, self.closed = 0, [], False
        self.callback, self.answers, self.names = None, answers, []
        fake = self

        hd = types.ModuleType("pyOpenHaptics.hd")
        # Column-major 4 x 4: the translation is transform[3][0..2], in mm.
        hd.get_transform = lambda: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [*fake.p_mm, 1]]
        hd.get_buttons = lambda: fake.buttons
        hd.set_force = lambda force: fake.forces.append(list(force))
        callback_module = types.ModuleType("pyOpenHaptics.hd_callback")
        callback_module.hd_callback = lambda function: function
        device_module = types.ModuleType("pyOpenHaptics.hd_device")

        class HapticDevice:
            def __init__(self, callback, device_name="Default Device", scheduler_type="async"):
                fake.callback = callback
                fake.names.append((device_name, scheduler_type))
                if fake.answers:
                    callback()  # the scheduler's first servo tick

            def close(self):
                fake.closed = True

        device_module.HapticDevice = HapticDevice
        package = types.ModuleType("pyOpenHaptics")
        package.hd, package.hd_callback, package.hd_device = hd, callback_module, device_module
        self.modules = {
            "pyOpenHaptics": package,
            "pyOpenHaptics.hd": hd,
            "pyOpenHaptics.hd_callback": callback_module,
            "pyOpenHaptics.hd_device": device_module,
        }

    def tick(self):
        self.callback()


@pytest.fixture
def openhaptics(monkeypatch):
    fake = FakeOpenHaptics()
    for name, module in fake.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    return fake


class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_touch_x_reports_metres_in_the_master_frame(openhaptics):
    openhaptics.p_mm = [12.0, -30.0, 45.0]
    device = TouchXDevice(p_MD=[0.0, 0.01, 0.0])
    assert openhaptics.names == [("Default Device", "async")]
    np.testing.assert_allclose(device.position(), [0.012, -0.030 + 0.01, 0.045], atol=1e-15)
    openhaptics.p_mm, openhaptics.buttons = [-80.0, 60.0, 0.0], 1
    openhaptics.tick()
    np.testing.assert_allclose(device.position(), [-0.080, 0.070, 0.0], atol=1e-15)
    assert device.buttons == 1 and device.servo_count == 2


def test_touch_x_turned_mount_rotates_positions_and_forces(openhaptics):
    # D turned 90 deg about M's y (up): x_D = -z_M, z_D = x_M.
    R_MD = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    openhaptics.p_mm = [10.0, 0.0, 0.0]
    clock = FakeClock()
    device = TouchXDevice(R_MD=R_MD, clock=clock)
    np.testing.assert_allclose(device.position(), [0.0, 0.0, -0.010], atol=1e-15)
    device.apply_force([3.0, 0.0, 0.0])  # along x_M = z_D
    openhaptics.tick()
    np.testing.assert_allclose(openhaptics.forces[-1], [0.0, 0.0, 3.0], atol=1e-15)


def test_touch_x_saturates_force_and_zeroes_it_when_commands_stop(openhaptics):
    clock = FakeClock()
    device = TouchXDevice(clock=clock)
    assert openhaptics.forces[-1] == [0.0, 0.0, 0.0]  # nothing commanded yet
    device.apply_force([0.0, 0.0, 20.0])
    openhaptics.tick()
    np.testing.assert_allclose(openhaptics.forces[-1], [0.0, 0.0, 7.9])
    clock.now += 0.049
    openhaptics.tick()
    np.testing.assert_allclose(openhaptics.forces[-1], [0.0, 0.0, 7.9])
    clock.now += 0.002  # 51 ms since the last command: the simulation stalled
    openhaptics.tick()
    assert openhaptics.forces[-1] == [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="f_MS must be 3 finite values"):
        device.apply_force([math.nan, 0.0, 0.0])
    device.apply_force([1.0, 0.0, 0.0])
    device.close()
    openhaptics.tick()
    assert openhaptics.closed and openhaptics.forces[-1] == [0.0, 0.0, 0.0]


def test_touch_x_drives_a_device_master(openhaptics):
    openhaptics.p_mm = [5.0, 5.0, 5.0]
    device = TouchXDevice()
    master = DeviceMaster(device=device)
    simulator = Simulator(master)
    master.get_motor_force_input_port().FixValue(simulator.get_mutable_context(), [0, 1.0, 0])
    simulator.AdvanceTo(0.0005)
    openhaptics.tick()
    np.testing.assert_allclose(
        master.get_p_MS_output_port().Eval(simulator.get_context()), [0.005] * 3
    )
    np.testing.assert_allclose(openhaptics.forces[-1], [0.0, 1.0, 0.0])


def test_touch_x_errors_say_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyOpenHaptics", None)
    monkeypatch.delitem(sys.modules, "pyOpenHaptics.hd", raising=False)
    with pytest.raises(ModuleNotFoundError, match=r"pip install 'hemg-drake\[touchx\]'"):
        TouchXDevice()
    silent = FakeOpenHaptics(answers=False)
    for name, module in silent.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    with pytest.raises(RuntimeError, match="no OpenHaptics device 'Default Device' answered"):
        TouchXDevice(answer_timeout=0.01)
    assert silent.closed
    with pytest.raises(ValueError, match="R_MD must be a 3 x 3 rotation"):
        TouchXDevice(R_MD=np.diag([1.0, 1.0, -1.0]))


def test_missing_sdk_library_is_named(monkeypatch):
    # pyOpenHaptics loads libHD.so when imported: an OSError without the SDK.
    class Finder:
        def find_spec(self, name, path=None, target=None):
            if name.startswith("pyOpenHaptics"):
                raise OSError("libHD.so: cannot open shared object file")
            return None

    for name in ("pyOpenHaptics", "pyOpenHaptics.hd"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    monkeypatch.setattr(sys, "meta_path", [Finder(), *sys.meta_path])
    with pytest.raises(RuntimeError, match="OpenHaptics SDK"):
        TouchXDevice()

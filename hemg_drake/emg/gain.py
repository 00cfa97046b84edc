"""Muscle activation and variable gain from the normalised envelope (eq. 22).

a(u) = (exp(A_emg u) - 1) / (exp(A_emg) - 1), u in [0, 1];
K = (K_max - K_min) (a - a_max) / (a_min - a_max) + K_min, clipped to [K_min, K_max].

The paper calls alpha_min the *upper* bound of the activation and alpha_max the
*lower* one (spec, sec. 3). Here they are named for what they are: ``a_rest``
(the activation at rest, the paper's alpha_max, a(0) = 0) and ``a_mvc`` (at
maximum voluntary contraction, the paper's alpha_min, a(1) = 1), so
K = (K_max - K_min) (a - a_rest) / (a_mvc - a_rest) + K_min: the strongest
contraction gives K_max, a stiffer slave.
"""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem

from hemg_drake.emg.calibration import EmgCalibration

A_EMG = -0.6981  # Table I
# Table I's Kp = 50 sits inside this range.
DEFAULT_K_MIN = 10.0
DEFAULT_K_MAX = 100.0


def _check_a_emg(A_emg):
    if not (np.isfinite(A_emg) and A_emg != 0):
        raise ValueError(f"A_emg must be finite and non-zero, got {A_emg!r}")


def _check_gains(k_min, k_max):
    if not (np.isfinite(k_min) and np.isfinite(k_max) and 0 <= k_min < k_max):
        raise ValueError(
            f"gains need 0 <= k_min < k_max, both finite; got k_min={k_min!r}, k_max={k_max!r}"
        )


def activation(u, A_emg=A_EMG):
    """Muscle activation a(u) of eq. 22; a(0) = 0, a(1) = 1, increasing in u.

    Parameters
    ----------
    u : float or array-like
        Normalised envelope in [0, 1] (not clipped here; see ``EmgCalibration``).
    A_emg : float
        Shape factor, non-zero (paper: -0.6981; negative gives a concave curve).

    Returns
    -------
    a : float or ndarray, same shape as ``u``
    """
    _check_a_emg(A_emg)
    u = np.asarray(u, dtype=float)
    return np.expm1(A_emg * u) / np.expm1(A_emg)


def gain_from_activation(a, *, k_min=DEFAULT_K_MIN, k_max=DEFAULT_K_MAX, a_rest=0.0, a_mvc=1.0):
    """Gain K of eq. 22, clipped to [k_min, k_max]; a = a_mvc gives k_max.

    Parameters
    ----------
    a : float or array-like
        Muscle activation.
    k_min, k_max : float
        Gain at rest and at maximum contraction (units of the gain driven,
        e.g. N·m/rad for a joint PD).
    a_rest, a_mvc : float
        Activation at rest (paper's alpha_max) and at maximum contraction
        (paper's alpha_min); defaults are a(0) and a(1).

    Returns
    -------
    K : float or ndarray, same shape as ``a``
    """
    _check_gains(k_min, k_max)
    if not (np.isfinite(a_rest) and np.isfinite(a_mvc) and a_rest != a_mvc):
        raise ValueError(f"a_rest and a_mvc must be finite and differ, got {a_rest!r}, {a_mvc!r}")
    a = np.asarray(a, dtype=float)
    K = (k_max - k_min) * (a - a_rest) / (a_mvc - a_rest) + k_min
    return np.clip(K, k_min, k_max)


class VariableGain(LeafSystem):
    """Muscle activation and slave gain from the sEMG envelope (eq. 22).

    .. pydrake_system::

        name: VariableGain
        input_ports:
        - envelope
        output_ports:
        - activation
        - gain

    ``envelope`` (1) is the raw RMS envelope from ``RmsEnvelope`` (MYO units);
    the ``calibration`` turns it into u in [0, 1] (the default calibration is
    the identity, for an envelope already normalised). ``activation`` (1,
    unitless) is a(u) in [0, 1]; ``gain`` (1) is K in [k_min, k_max], in the
    units of the gain it drives.

    Timing: stateless, direct feedthrough; evaluated whenever a consumer asks.

    Modelling choice: a NaN envelope (a lost or corrupt sEMG sample) gives
    activation 0 and gain k_min, the compliant, safe side, rather than holding
    a possibly stiff last gain; nothing NaN leaves this system.

    Parameters
    ----------
    calibration : EmgCalibration, optional
        Rest and MVC levels of the envelope; None means identity.
    A_emg : float
        Shape factor of a(u) (default -0.6981, Table I).
    k_min, k_max : float
        Gain at rest and at maximum contraction.
    """

    def __init__(self, *, calibration=None, A_emg=A_EMG, k_min=DEFAULT_K_MIN, k_max=DEFAULT_K_MAX):
        LeafSystem.__init__(self)
        _check_a_emg(A_emg)
        _check_gains(k_min, k_max)
        if calibration is not None and not isinstance(calibration, EmgCalibration):
            raise ValueError(f"calibration must be an EmgCalibration or None, got {calibration!r}")
        self._calibration = EmgCalibration() if calibration is None else calibration
        self._A_emg = float(A_emg)
        self._expm1_A = math.expm1(self._A_emg)
        self._k_min, self._k_max = float(k_min), float(k_max)
        self._envelope_input = self.DeclareVectorInputPort("envelope", 1)
        # A function of the envelope alone: recomputed when it changes (200 Hz), not at
        # every time step.
        envelope_only = {self._envelope_input.ticket()}
        self._activation_output = self.DeclareVectorOutputPort(
            "activation", 1, self._calc_activation, prerequisites_of_calc=envelope_only
        )
        self._gain_output = self.DeclareVectorOutputPort(
            "gain", 1, self._calc_gain, prerequisites_of_calc=envelope_only
        )

    def get_envelope_input_port(self):
        return self._envelope_input

    def get_activation_output_port(self):
        return self._activation_output

    def get_gain_output_port(self):
        return self._gain_output

    def _activation(self, context):
        u = float(self._calibration.normalise(self._envelope_input.Eval(context)[0]))
        return 0.0 if math.isnan(u) else math.expm1(self._A_emg * u) / self._expm1_A

    def _calc_activation(self, context, output):
        output.SetAtIndex(0, self._activation(context))

    def _calc_gain(self, context, output):
        # gain_from_activation's law on plain floats (a is in [0, 1], so K needs no clip).
        a = self._activation(context)
        output.SetAtIndex(0, (self._k_max - self._k_min) * a + self._k_min)

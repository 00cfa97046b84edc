"""Muscle activation and variable gain from the normalised envelope (eq. 22).

a(u) = (exp(A_emg u) - 1) / (exp(A_emg) - 1), u in [0, 1];
K = (K_max - K_min) (a - a_max) / (a_min - a_max) + K_min, clipped to [K_min, K_max].

The paper calls alpha_min the *upper* bound of the activation and alpha_max the
*lower* one (spec, sec. 3). Here they are named for what they are: ``a_rest``
(the activation at rest, the paper's alpha_max, a(0) = 0) and ``a_mvc`` (at
maximum voluntary contraction, the paper's alpha_min, a(1) = 1), so
K = (K_max - K_min) (a - a_rest) / (a_mvc - a_rest) + K_min: the strongest
contraction gives K_max, a stiffer slave.

The law is :func:`activation` and :func:`gain_from_activation`; ``VariableGain`` calls
them in its output ports, the Fig. 6 / eq. 22 figures call them on arrays.
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, LeafSystem_, NumericParameterIndex
from pydrake.systems.scalar_conversion import TemplateSystem

from hemg_drake.emg.calibration import EmgCalibration, normalised_envelope
from hemg_drake.emg.config import GainConfig

_DEFAULT = GainConfig()
# Table I's shape factor, and the default gain range (the config's values, for the figures).
A_EMG = _DEFAULT.A_emg
DEFAULT_K_MIN = _DEFAULT.k_min
DEFAULT_K_MAX = _DEFAULT.k_max


def _check_a_emg(A_emg):
    if not (math.isfinite(A_emg) and A_emg != 0):
        raise ValueError(f"A_emg must be finite and non-zero, got {A_emg!r}")


def _check_gains(k_min, k_max):
    if not (math.isfinite(k_min) and math.isfinite(k_max) and 0 <= k_min < k_max):
        raise ValueError(
            f"gains need 0 <= k_min < k_max, both finite; got k_min={k_min!r}, k_max={k_max!r}"
        )


def activation(u, A_emg=A_EMG):
    """Muscle activation a(u) of eq. 22; a(0) = 0, a(1) = 1, increasing in u.

    Parameters
    ----------
    u : float or array-like
        Normalised envelope in [0, 1] (not clipped here; see ``normalised_envelope``).
    A_emg : float
        Shape factor, non-zero (paper: -0.6981; negative gives a concave curve).

    Returns
    -------
    a : float or ndarray, same shape as ``u`` (AutoDiffXd entries stay AutoDiffXd)
    """
    _check_a_emg(A_emg)
    u = np.asarray(u)
    if u.dtype != object:
        return np.expm1(A_emg * u.astype(float)) / math.expm1(A_emg)
    return (np.exp(A_emg * u) - 1.0) / math.expm1(A_emg)  # AutoDiffXd has no expm1


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
    if not (math.isfinite(a_rest) and math.isfinite(a_mvc) and a_rest != a_mvc):
        raise ValueError(f"a_rest and a_mvc must be finite and differ, got {a_rest!r}, {a_mvc!r}")
    a = np.asarray(a)
    if a.dtype != object:
        a = a.astype(float)
    K = (k_max - k_min) * (a - a_rest) / (a_mvc - a_rest) + k_min
    return np.minimum(np.maximum(K, k_min), k_max)


# The numeric parameter of VariableGain, in this order.
GAIN_PARAMETERS = ("A_emg", "k_min", "k_max", "rest_level", "mvc_level")


@TemplateSystem.define("VariableGain_", T_list=(float, AutoDiffXd))
def VariableGain_(T):
    class Impl(LeafSystem_[T]):
        """Muscle activation and slave gain from the sEMG envelope (eq. 22).

        .. pydrake_system::

            name: VariableGain
            input_ports:
            - envelope
            output_ports:
            - activation
            - gain

        ``envelope`` (1) is the raw RMS envelope from ``RmsEnvelope`` (MYO units); the
        calibration levels turn it into u in [0, 1] (``normalised_envelope``; the default
        calibration is the identity, for an envelope already normalised). ``activation``
        (1, unitless) is a(u) in [0, 1] (:func:`activation`); ``gain`` (1) is K in
        [k_min, k_max] (:func:`gain_from_activation`), in the units of the gain it drives.

        Parameters in the Context: one numeric parameter holding ``GAIN_PARAMETERS``
        (A_emg, k_min, k_max, rest_level, mvc_level), defaults from ``config`` and
        ``calibration``; ``set_parameters`` changes them in one context.

        Timing: stateless, direct feedthrough; each output is recomputed only when the
        envelope or the parameters change (200 Hz), not at every time step.

        Modelling choice: a NaN envelope (a lost or corrupt sEMG sample) gives activation 0
        and gain k_min, the compliant, safe side, rather than holding a possibly stiff last
        gain; nothing NaN leaves this system.

        Parameters
        ----------
        config : GainConfig
            A_emg, k_min, k_max.
        calibration : EmgCalibration, optional
            Rest and MVC levels of the envelope; None means identity.
        """

        def _construct(self, *, config=GainConfig(), calibration=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if calibration is not None and not isinstance(calibration, EmgCalibration):
                raise ValueError(
                    f"calibration must be an EmgCalibration or None, got {calibration!r}"
                )
            calibration = EmgCalibration() if calibration is None else calibration
            _check_a_emg(config.A_emg)
            _check_gains(config.k_min, config.k_max)
            self._config, self._calibration = config, calibration
            values = [config.A_emg, config.k_min, config.k_max,
                      calibration.rest_level, calibration.mvc_level]  # fmt: skip
            self._parameter = self.DeclareNumericParameter(BasicVector_[T](values))
            self._envelope_input = self.DeclareVectorInputPort("envelope", 1)
            inputs = {self._envelope_input.ticket(), self.numeric_parameter_ticket(NumericParameterIndex(self._parameter))}
            self._activation_output = self.DeclareVectorOutputPort(
                "activation", 1, self._calc_activation, prerequisites_of_calc=inputs
            )
            self._gain_output = self.DeclareVectorOutputPort(
                "gain", 1, self._calc_gain, prerequisites_of_calc=inputs
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, config=other._config, calibration=other._calibration, converter=converter
            )

        def get_envelope_input_port(self):
            return self._envelope_input

        def get_activation_output_port(self):
            return self._activation_output

        def get_gain_output_port(self):
            return self._gain_output

        def set_parameters(self, context, *, config=None, calibration=None):
            """Write a gain config's and/or a calibration's values into ``context``."""
            values = context.get_mutable_numeric_parameter(self._parameter)
            if config is not None:
                _check_a_emg(config.A_emg)
                _check_gains(config.k_min, config.k_max)
                for i, value in enumerate((config.A_emg, config.k_min, config.k_max)):
                    values.SetAtIndex(i, value)
            if calibration is not None:
                values.SetAtIndex(3, calibration.rest_level)
                values.SetAtIndex(4, calibration.mvc_level)

        def _activation(self, context):
            A_emg, _, _, rest, mvc = context.get_numeric_parameter(self._parameter).CopyToVector()
            u = normalised_envelope(self._envelope_input.Eval(context)[0], rest, mvc)
            if T == float and math.isnan(u):
                return 0.0
            return np.asarray(activation(u, _value(A_emg))).item()

        def _calc_activation(self, context, output):
            output.SetAtIndex(0, self._activation(context))

        def _calc_gain(self, context, output):
            _, k_min, k_max, _, _ = context.get_numeric_parameter(self._parameter).CopyToVector()
            a = self._activation_output.Eval(context)[0]  # cached: a(u) once per envelope
            K = gain_from_activation(a, k_min=_value(k_min), k_max=_value(k_max))
            output.SetAtIndex(0, np.asarray(K).item())

    return Impl


def _value(x):
    """A parameter as a float (its AutoDiffXd value: the law's constants are not inputs)."""
    return x.value() if isinstance(x, AutoDiffXd) else float(x)


VariableGain = VariableGain_[None]

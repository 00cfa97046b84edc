"""The synthetic MYO: raw 8-channel sEMG whose amplitude follows a muscle activation.

``make_synthetic_emg_source`` builds a small diagram of Drake's ``RandomSource`` (unit Gaussian noise,
one draw per sample; its seed is the Context's, set by ``SetRandomContext``), the law
``SyntheticEmgLaw`` (:func:`synthetic_emg_sample`) and Drake's ``ZeroOrderHold``, which takes
sample k at t_k = k / 200 s and holds it (zero before the first). :func:`synthesize_emg`
runs that diagram for a sequence of activations: the offline recordings (calibration, the
Fig. 6 figure) are the system's own output.
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector_, DiagramBuilder, LeafSystem_
from pydrake.systems.primitives import (
    LogVectorOutput,
    RandomSource,
    TrajectorySource,
    ZeroOrderHold,
)
from pydrake.systems.scalar_conversion import TemplateSystem
from pydrake.trajectories import PiecewisePolynomial

from hemg_drake._validate import as_scalar, as_seed
from hemg_drake.emg.config import (
    INT8_MAX,
    INT8_MIN,
    MYO_CHANNELS,
    MYO_PERIOD,
    SyntheticEmgConfig,
)

# Samples whose noise is drawn at once (one second at 200 Hz): the RandomSource's block.
NOISE_BLOCK = 200


def _checked_config(config):
    gains = np.asarray(config.channel_gains, dtype=float)
    if gains.shape != (MYO_CHANNELS,) or not np.all(np.isfinite(gains) & (gains >= 0)):
        raise ValueError(
            f"channel_gains must be {MYO_CHANNELS} finite non-negative numbers, "
            f"got {config.channel_gains!r}"
        )
    if not (np.isfinite(config.rest_std) and config.rest_std >= 0):
        raise ValueError(f"rest_std must be finite and >= 0, got {config.rest_std!r}")
    if not (np.isfinite(config.exponent) and config.exponent > 0):
        raise ValueError(f"exponent must be finite and > 0, got {config.exponent!r}")
    return np.concatenate([gains, [config.rest_std, config.exponent]])


def synthetic_emg_sample(activation, noise, channel_gains, rest_std, exponent):
    """One synthetic MYO sample: clip(round((rest_std + g_i a^p) n_i), -128, 127).

    Parameters
    ----------
    activation : float
        Muscle activation; clipped to [0, 1], NaN reads as 0 (rest).
    noise : ndarray, shape (8,)
        Unit Gaussian noise n_i.
    channel_gains : ndarray, shape (8,)
        g_i: standard deviation added per channel at full activation (MYO units).
    rest_std : float
        Standard deviation at rest (MYO units).
    exponent : float
        p.

    Returns
    -------
    emg : ndarray, shape (8,)
        Integer-valued floats in -128..127 (``np.round``: half to even).
    """
    a = 0.0 if np.isnan(activation) else min(max(float(activation), 0.0), 1.0)
    sample = np.round((rest_std + channel_gains * a**exponent) * noise)
    return np.minimum(np.maximum(sample, INT8_MIN), INT8_MAX)


@TemplateSystem.define("SyntheticEmgLaw_", T_list=(float, AutoDiffXd))
def SyntheticEmgLaw_(T):
    class Impl(LeafSystem_[T]):
        """The synthetic MYO's law: a sample from an activation and unit noise.

        .. pydrake_system::

            name: SyntheticEmgLaw
            input_ports:
            - activation
            - noise
            output_ports:
            - emg

        ``activation`` (1, unitless), ``noise`` (``NOISE_BLOCK`` x 8 unit Gaussians, row by
        row), ``emg`` (8, MYO units): :func:`synthetic_emg_sample` of the activation and
        noise row k mod ``NOISE_BLOCK``, k = round(t / period) the sample's index (Sec. II-B's
        armband; a stand-in for the MYO, not a physiological model); stateless, direct
        feedthrough. The channel gains, rest_std and exponent are a numeric parameter (10
        values, in that order). Converted to
        AutoDiffXd (as a Clone needs a conversion), the samples carry zero derivatives: the
        rounding to integers is piecewise constant.

        Parameters
        ----------
        config : SyntheticEmgConfig
        period : float
            Sample period in s.
        """

        def _construct(self, *, config=SyntheticEmgConfig(), period=MYO_PERIOD, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._config, self._period = config, as_scalar("period", period)
            self._parameter = self.DeclareNumericParameter(BasicVector_[T](_checked_config(config)))
            self._activation_input = self.DeclareVectorInputPort("activation", 1)
            self._noise_input = self.DeclareVectorInputPort("noise", NOISE_BLOCK * MYO_CHANNELS)
            self.DeclareVectorOutputPort("emg", MYO_CHANNELS, self._calc_emg)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, config=other._config, period=other._period, converter=converter)

        def _calc_emg(self, context, output):
            p = _values(context.get_numeric_parameter(self._parameter).CopyToVector())
            row = round(_float(context.get_time()) / self._period) % NOISE_BLOCK
            noise = _values(self._noise_input.Eval(context))
            sample = synthetic_emg_sample(
                _values(self._activation_input.Eval(context))[0],
                noise[row * MYO_CHANNELS : (row + 1) * MYO_CHANNELS],
                p[:MYO_CHANNELS],
                p[MYO_CHANNELS],
                p[MYO_CHANNELS + 1],
            )
            output.SetFromVector(sample if T == float else [AutoDiffXd(x) for x in sample])

    return Impl


def _float(x):
    return x.value() if isinstance(x, AutoDiffXd) else float(x)


def _values(vector):
    """A vector's values as floats: itself for float, the AutoDiffXd values otherwise."""
    return vector if vector.dtype != object else ExtractValue(vector)[:, 0]


SyntheticEmgLaw = SyntheticEmgLaw_[None]


def make_synthetic_emg_source(*, config=SyntheticEmgConfig(), period=MYO_PERIOD):
    """Synthetic MYO-like raw sEMG whose amplitude grows with muscle activation.

    .. pydrake_system::

        name: emg_source
        input_ports:
        - activation
        output_ports:
        - emg

    ``activation`` (1, unitless) is the muscle activation; it is clipped to [0, 1], and a
    NaN reads as 0 (rest). ``emg`` (8, MYO units) holds integers in -128..127.

    Model (Sec. II-B; a stand-in for the MYO, not a physiological model): each channel i is
    zero-mean Gaussian noise with standard deviation std_i = rest_std + channel_gains[i] *
    activation^exponent, rounded to an integer and clipped to int8. With the default
    exponent 1 the RMS envelope of the channel sum grows linearly with activation (up to
    clipping, rare below 3 std = 127), so after an ``EmgCalibration`` from rest and MVC
    recordings the normalised envelope is close to the activation itself.

    Inside: ``noise`` (Drake's ``RandomSource``: ``NOISE_BLOCK`` x 8 unit Gaussians, redrawn
    every ``NOISE_BLOCK`` periods, i.e. once a second), ``law`` (``SyntheticEmgLaw``, which
    takes row k mod ``NOISE_BLOCK`` for sample k), ``hold`` (Drake's ``ZeroOrderHold``).
    Timing: at t_k = k * period the hold samples the law, which reads the activation and
    sample k's noise; the output holds sample k until t_{k+1}, zero before the first. The
    noise is drawn a block at a time because a ``RandomSource`` updates through an
    unrestricted update, which invalidates every state-dependent cache of the diagram: once
    per sample it cost a demonstration about 65 ms of CPU per simulated second (15 %),
    once per block it costs nothing measurable. The noise is in
    the Context: ``diagram.SetRandomContext(context, RandomGenerator(seed))`` seeds it (same
    seed, same samples); a default Context's noise depends on how many random sources the
    process built before, so always seed it.

    Parameters
    ----------
    config : SyntheticEmgConfig
    period : float
        Sample period in s (MYO: 1/200).

    Returns
    -------
    Diagram
        Named ``emg_source``; input port ``activation``, output port ``emg``.
    """
    period = as_scalar("period", period)
    block = NOISE_BLOCK * period
    # The noise's blocks must begin exactly at a sample instant (Drake times periodic events
    # at offset + n * period): true of 1/200 s, checked for the first 10^5 blocks.
    n = np.arange(1, 100_001, dtype=float)
    if not np.array_equal(n * block, (n * NOISE_BLOCK) * period):
        raise ValueError(
            f"period {period!r}: {NOISE_BLOCK} periods do not add up exactly to a block; "
            f"use the MYO's 1/200 s"
        )
    builder = DiagramBuilder()
    noise = builder.AddNamedSystem(
        "noise", RandomSource(RandomDistribution.kGaussian, NOISE_BLOCK * MYO_CHANNELS, block)
    )
    law = builder.AddNamedSystem("law", SyntheticEmgLaw(config=config, period=period))
    hold = builder.AddNamedSystem("hold", ZeroOrderHold(period, MYO_CHANNELS))
    builder.Connect(noise.get_output_port(), law.GetInputPort("noise"))
    builder.Connect(law.GetOutputPort("emg"), hold.get_input_port())
    builder.ExportInput(law.GetInputPort("activation"), "activation")
    builder.ExportOutput(hold.get_output_port(), "emg")
    diagram = builder.Build()
    diagram.set_name("emg_source")
    return diagram


def held_samples(values, period=MYO_PERIOD):
    """A ``TrajectorySource`` holding ``values[k]`` around each sample instant t_k = k T.

    Its breaks sit a quarter period before each sample instant, away from the sources'
    updates (t_k) and the envelope's (t_k + T/2), so every system of the chain reads
    ``values[k]`` for sample k whatever the rounding of k * T.

    Parameters
    ----------
    values : array-like, shape (n_samples,) or (n_samples, size)
    period : float
        T in s.

    Returns
    -------
    TrajectorySource
        Its output has size 1, or ``size``; after the last sample it holds the last row.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    breaks = np.concatenate([[0.0], (np.arange(1, len(values) + 1) - 0.25) * period])
    knots = np.vstack([values, values[-1:]]).T
    return TrajectorySource(PiecewisePolynomial.ZeroOrderHold(breaks, knots))


def synthesize_emg(activation, seed, *, config=SyntheticEmgConfig()):
    """Synthetic MYO-like raw sEMG for a sequence of muscle activations, seeded.

    Runs ``make_synthetic_emg_source()`` (the one implementation) with sample k reading
    ``activation[k]`` and its Context seeded by ``RandomGenerator(seed)``: a source seeded
    with ``seed`` in the same way gives the same samples.

    Parameters
    ----------
    activation : array-like, shape (n_samples,)
        Muscle activation per 200 Hz sample; clipped to [0, 1]. NaN is rejected.
    seed : int
        Non-negative seed; the same seed gives the same samples.
    config : SyntheticEmgConfig

    Returns
    -------
    emg : ndarray of int64, shape (n_samples, 8)
        Integers in -128..127.
    """
    seed = as_seed(seed)
    activation = np.asarray(activation, dtype=float)
    if activation.ndim != 1 or len(activation) == 0:
        raise ValueError(f"activation must have shape (n_samples > 0,), got {activation.shape}")
    if np.any(np.isnan(activation)):
        raise ValueError("activation contains NaN")
    builder = DiagramBuilder()
    source = builder.AddSystem(make_synthetic_emg_source(config=config))
    signal = builder.AddNamedSystem("activation", held_samples(activation))
    builder.Connect(signal.get_output_port(), source.GetInputPort("activation"))
    logger = LogVectorOutput(source.GetOutputPort("emg"), builder, publish_period=MYO_PERIOD)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    diagram.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(seed))
    simulator.AdvanceTo(len(activation) * MYO_PERIOD)
    # A logger publishing at t_k sees the hold before its update at t_k: row k + 1 holds
    # sample k.
    data = logger.FindLog(simulator.get_context()).data().T[1 : len(activation) + 1]
    return data.astype(np.int64)

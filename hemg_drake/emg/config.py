"""Settings of the sEMG chain: source, RMS envelope (eqs. 1-2), gain law (eq. 22).

``EmgConfig`` is the scenario's flat ``emg`` section; each system of the chain takes its own
config, which ``EmgConfig`` hands out (``envelope()``, ``gain()``), so the YAML keys stay
``emg.window``, ``emg.k_max``, ... while every default is written once, here.
"""

import dataclasses as dc

from hemg_drake.config_fields import checked, key_path

# Where a demonstration's raw sEMG comes from (emg.source).
EMG_SOURCES = ("synthetic", "myo", "libemg")
# The MYO armband: sample rate (Hz), period (s), channels, raw sample range (int8).
MYO_RATE = 200.0
MYO_PERIOD = 1.0 / MYO_RATE
MYO_CHANNELS = 8
INT8_MIN, INT8_MAX = -128, 127
# Longest calibration recording (s): a minute each of rest and contraction is 12 000 samples
# of 8 channels; the shipped scenarios take 2 s (1e9 s would ask for 13 TB).
MAX_CALIBRATION_DURATION = 60.0


@dc.dataclass
class EnvelopeConfig:
    """The moving-RMS envelope (``RmsEnvelope``, eqs. 1-2)."""

    # Moving-RMS window L_win in samples (the paper compares 10, 20, 30 and picks 20).
    window: int = checked(20, positive=True)
    # RMS per channel, then summed, instead of the paper's RMS of the channel sum.
    per_channel: bool = checked(False)


@dc.dataclass
class GainConfig:
    """The activation and gain law (``VariableGain``, eq. 22)."""

    # Shape factor of the activation curve (Table I); non-zero.
    A_emg: float = checked(-0.6981, signed=True)
    # Gain K at rest and at maximum contraction (VariableGainPd's K; its tested range is
    # 5 to 500, Table I's 50 sits between).
    k_min: float = checked(10.0)
    k_max: float = checked(100.0)


@dc.dataclass
class SyntheticEmgConfig:
    """The synthetic MYO (``make_synthetic_emg_source``): std_i = rest_std + g_i a^exponent."""

    # Noise standard deviation added per channel at full activation (MYO units). Electrodes
    # around the forearm see the contracting muscle unequally: the pods over the muscle
    # belly (first and last here) most, those across the arm least.
    channel_gains: list[float] = checked(
        [40.0, 34.0, 26.0, 20.0, 20.0, 26.0, 34.0, 40.0], size=MYO_CHANNELS
    )
    # Standard deviation at rest (electrode and amplifier noise), in MYO units.
    rest_std: float = checked(2.0)
    # p in std = rest_std + gain * activation^p.
    exponent: float = checked(1.0, positive=True)


_ENVELOPE, _GAIN = EnvelopeConfig(), GainConfig()


@dc.dataclass
class EmgConfig:
    """sEMG chain: synthetic MYO source, RMS envelope (eqs. 1-2), gain law (eq. 22).

    Flat, as the scenario's YAML keys are; ``envelope()`` and ``gain()`` hand each system
    its own config.
    """

    def envelope(self):
        """The envelope's settings: an ``EnvelopeConfig``."""
        return EnvelopeConfig(window=self.window, per_channel=self.per_channel)

    def gain(self):
        """The gain law's settings: a ``GainConfig``."""
        return GainConfig(A_emg=self.A_emg, k_min=self.k_min, k_max=self.k_max)

    # Moving-RMS window L_win in 200 Hz samples (EnvelopeConfig.window).
    window: int = checked(_ENVELOPE.window, positive=True)
    # RMS per channel, then summed, instead of the paper's RMS of the channel sum.
    per_channel: bool = checked(_ENVELOPE.per_channel)
    # Shape factor of the activation curve (GainConfig.A_emg, Table I).
    A_emg: float = checked(_GAIN.A_emg, signed=True)
    # Gain K at rest and at maximum contraction (GainConfig).
    k_min: float = checked(_GAIN.k_min)
    k_max: float = checked(_GAIN.k_max)
    # Length of the synthetic rest and maximum-contraction recordings (s) from which the
    # envelope's calibration is computed before each demonstration.
    calibration_duration: float = checked(2.0, positive=True, maximum=MAX_CALIBRATION_DURATION)
    # Where the raw sEMG comes from: "synthetic" (make_synthetic_emg_source, driven by the
    # operator's activation), or a live armband read by LiveEmgSource: "myo" (pyomyo,
    # hemg-drake[myo]) or "libemg" (a LibEMG streamer's shared memory, tag libemg_tag).
    # A live source needs the simulator at real time (simulator.target_realtime_rate: 1,
    # as hemg-drake teleop runs).
    source: str = checked("synthetic", choices=EMG_SOURCES)
    libemg_tag: str = "emg"

    def check(self, key=""):
        """The rules between fields (their ranges are the fields' own): a non-zero A_emg
        (eq. 22 divides by exp(A_emg) - 1), k_min < k_max, and a calibration at least one
        RMS window long. Raises ValueError naming the keys under ``key``."""
        if self.A_emg == 0:
            raise ValueError(
                f"key '{key_path(key, 'A_emg')}' must not be 0 (eq. 22 divides by "
                "exp(A_emg) - 1)"
            )
        if not self.k_min < self.k_max:
            raise ValueError(
                f"keys '{key_path(key, 'k_min')}' < '{key_path(key, 'k_max')}' required, got "
                f"{self.k_min}, {self.k_max}"
            )
        calibration_samples = int(round(self.calibration_duration * MYO_RATE))
        if calibration_samples < self.window:
            raise ValueError(
                f"key '{key_path(key, 'calibration_duration')}' gives {calibration_samples} "
                f"samples, fewer than the window '{key_path(key, 'window')}' = {self.window}: "
                "no envelope to calibrate"
            )

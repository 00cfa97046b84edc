"""Settings of the sEMG chain: source, RMS envelope (eqs. 1-2), gain law (eq. 22).
"""

import dataclasses as dc

from hemg_drake.config_fields import checked, key_path

# Where a demonstration's raw sEMG comes from (emg.source).
EMG_SOURCES = ("synthetic", "myo", "libemg")
# The MYO armband's sample rate (Hz).
MYO_RATE = 200.0


@dc.dataclass
class EmgConfig:
    """sEMG chain: synthetic MYO source, RMS envelope (eqs. 1-2), gain law (eq. 22)."""

    # Moving-RMS window L_win in 200 Hz samples (the paper picks 20).
    window: int = checked(20, positive=True)
    # RMS per channel, then summed, instead of the paper's RMS of the channel sum.
    per_channel: bool = checked(False)
    # Shape factor of the activation curve (Table I).
    A_emg: float = checked(-0.6981, signed=True)
    # Gain K at rest and at maximum contraction (VariableGainPd's K; its tested range is
    # 5 to 500, Table I's 50 sits between).
    k_min: float = checked(10.0)
    k_max: float = checked(100.0)
    # Length of the synthetic rest and maximum-contraction recordings (s) from which the
    # envelope's calibration is computed before each demonstration.
    calibration_duration: float = checked(2.0, positive=True)
    # Where the raw sEMG comes from: "synthetic" (SyntheticEmgSource, driven by the
    # operator's activation), or a live armband read by LiveEmgSource: "myo" (pyomyo,
    # hemg-drake[myo]) or "libemg" (a LibEMG streamer's shared memory, tag libemg_tag).
    # A live source needs the simulator at real time (simulator.target_realtime_rate: 1,
    # as hemg-drake teleop runs).
    source: str = checked("synthetic", choices=EMG_SOURCES)
    libemg_tag: str = "emg"

    def check(self, key=""):
        """The rules between fields (their ranges are the fields' own): k_min < k_max, and a
        calibration at least one RMS window long. Raises ValueError naming the keys under
        ``key``."""
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

"""Sources of raw sEMG at 200 Hz, MYO-like, in one import: synthetic, file replay, live.

Every source outputs the MYO's raw samples on a port named ``emg``: 8 channels, integers in
the signed 8-bit range -128..127 (carried as float64 in Drake vector ports), one sample per
1/200 s (facts: ``docs/facts.md``, MYO section). Sample k is output from t = k / 200 s until
the next one, and the output is zero before the first; as with any Drake discrete update, a
logger publishing at exactly t = k / 200 still sees sample k - 1.

- :func:`~hemg_drake.emg.synthetic.make_synthetic_emg_source` (``synthetic.py``): noise from
  the Context's ``RandomSource``, amplitude from the ``activation`` input;
- :func:`~hemg_drake.emg.recording.make_file_emg_source` (``recording.py``): a recording
  replayed by a ``TrajectorySource`` and a ``ZeroOrderHold``;
- :class:`~hemg_drake.emg.live.LiveEmgSource` (``live.py``): a live armband's samples, in
  order, any channel count and units.
"""

from hemg_drake.emg.config import INT8_MAX, INT8_MIN, MYO_CHANNELS, MYO_PERIOD, MYO_RATE
from hemg_drake.emg.live import (
    DEFAULT_MAX_BACKLOG,
    LIVE_COUNTERS,
    LIVE_UNITS,
    EmgDeviceStalled,
    LiveEmgSource,
    open_myo_device,
)
from hemg_drake.emg.recording import (
    NPZ_KEY,
    load_emg_recording,
    make_file_emg_source,
    save_emg_recording,
)
from hemg_drake.emg.synthetic import (
    SyntheticEmgLaw,
    held_samples,
    make_synthetic_emg_source,
    synthesize_emg,
    synthetic_emg_sample,
)

__all__ = [
    "DEFAULT_MAX_BACKLOG", "INT8_MAX", "INT8_MIN", "LIVE_COUNTERS", "LIVE_UNITS", "MYO_CHANNELS",
    "MYO_PERIOD", "MYO_RATE", "NPZ_KEY", "EmgDeviceStalled", "LiveEmgSource", "SyntheticEmgLaw",
    "held_samples", "load_emg_recording", "make_file_emg_source", "make_synthetic_emg_source",
    "open_myo_device", "save_emg_recording", "synthesize_emg", "synthetic_emg_sample",
]  # fmt: skip

"""Rest / maximum-voluntary-contraction calibration of the RMS envelope to [0, 1]."""

import dataclasses
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from hemg_drake.emg.envelope import DEFAULT_WINDOW, _check_window, moving_rms
from hemg_drake.fileio import write_text_atomic


def normalised_envelope(envelope, rest_level, mvc_level):
    """The envelope mapped to [0, 1]: u = clip((envelope - rest) / (mvc - rest), 0, 1).

    ``EmgCalibration.normalise`` and ``VariableGain`` both call it; NaN stays NaN.

    Parameters
    ----------
    envelope : float or ndarray, any shape
    rest_level, mvc_level : float
        Envelope at rest and at maximum voluntary contraction, rest_level < mvc_level.

    Returns
    -------
    u : ndarray, same shape
    """
    return np.minimum(np.maximum((envelope - rest_level) / (mvc_level - rest_level), 0.0), 1.0)


@dataclasses.dataclass
class EmgCalibration:
    """Maps an RMS envelope to [0, 1]: u = clip((rms - rest) / (mvc - rest), 0, 1).

    The defaults (rest 0, MVC 1) are the identity on an already normalised
    envelope. ``window`` and ``per_channel`` record how the levels were
    measured, so the envelope being normalised must use the same settings.

    Attributes
    ----------
    rest_level : float
        Mean envelope at rest (MYO units).
    mvc_level : float
        Mean envelope at maximum voluntary contraction (MYO units); > rest_level.
    window : int
        L_win of the envelope the levels were measured with.
    per_channel : bool
        Whether that envelope was the per-channel form.
    """

    # Mean RMS envelope of the rest recording (MYO units).
    rest_level: float = 0.0
    # Mean RMS envelope of the maximum-contraction recording (MYO units).
    mvc_level: float = 1.0
    # L_win of the envelope the levels were measured with.
    window: int = DEFAULT_WINDOW
    # True when the levels are of the per-channel envelope.
    per_channel: bool = False

    def __post_init__(self):
        self.validate()

    def validate(self):
        """Raise ValueError unless 0 <= rest_level < mvc_level, both finite, window >= 1."""
        rest, mvc = self.rest_level, self.mvc_level
        if not (np.isfinite(rest) and np.isfinite(mvc) and 0 <= rest < mvc):
            raise ValueError(
                f"calibration needs finite levels with 0 <= rest_level < mvc_level, "
                f"got rest_level={rest!r}, mvc_level={mvc!r}"
            )
        _check_window(self.window)

    @classmethod
    def from_recordings(cls, rest, mvc, window=DEFAULT_WINDOW, *, per_channel=False):
        """Levels from a rest and a maximum-contraction recording.

        Each level is the mean of the recording's ``moving_rms`` envelope,
        leaving out the first ``window - 1`` values (partial windows). A
        sustained maximal contraction therefore normalises to about 1 on
        average, its noise clipped above; with the synthetic source the
        normalised envelope is close to the activation (within about 0.05
        between 0.2 and 0.8).

        Parameters
        ----------
        rest, mvc : array-like, shape (n_samples, 8)
            Raw sEMG; each needs at least ``window`` samples.
        window : int
        per_channel : bool

        Returns
        -------
        EmgCalibration
        """
        levels = []
        for name, samples in (("rest", rest), ("mvc", mvc)):
            envelope = moving_rms(samples, window, per_channel=per_channel)
            if len(envelope) < window:
                raise ValueError(
                    f"the {name} recording needs at least window={window} samples, "
                    f"got {len(envelope)}"
                )
            levels.append(float(envelope[window - 1 :].mean()))
        return cls(
            rest_level=levels[0], mvc_level=levels[1], window=int(window), per_channel=per_channel
        )

    def normalise(self, envelope):
        """Envelope mapped to [0, 1] (clipped); NaN stays NaN.

        Parameters
        ----------
        envelope : float or array-like, any shape

        Returns
        -------
        u : float or ndarray, same shape
        """
        return normalised_envelope(
            np.asarray(envelope, dtype=float), self.rest_level, self.mvc_level
        )

    def save(self, path):
        """Write as YAML (atomically)."""
        write_text_atomic(path, yaml_dump_typed(self))

    @classmethod
    def load(cls, path):
        """Read a YAML file written by ``save`` (or by hand, same keys); validated."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"calibration file not found: {path}")
        try:
            calibration = yaml_load_typed(schema=cls, filename=str(path))
        except RuntimeError as error:
            raise ValueError(f"{path}: {error}") from None
        try:
            calibration.validate()
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
        return calibration

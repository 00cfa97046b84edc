"""The paper's figures, as plain functions returning matplotlib Figures.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot state), so they
work under any backend; ``save_figure`` writes one atomically. By concept:
:mod:`~hemg_drake.viz.figures.common` (saving, the stiffness's labels, signals against
time), :mod:`~hemg_drake.viz.figures.emg` (Fig. 6, eq. 22),
:mod:`~hemg_drake.viz.figures.learning` (demonstrations, reproductions, Fig. 8 (c), the GMR
field) and :mod:`~hemg_drake.viz.figures.tasks` (Fig. 8 (d)-(f), Fig. 10, Fig. 11, the
placements), :mod:`~hemg_drake.viz.figures.stability` (the loop's spectral radius against
delay); every name is importable from here.
"""

from hemg_drake.viz.figures.common import (
    STIFFNESS_LABEL,
    STIFFNESS_NOTE,
    STIFFNESS_UNIT,
    plot_time_series,
    save_figure,
)
from hemg_drake.viz.figures.emg import plot_emg_envelopes, plot_gain_law
from hemg_drake.viz.figures.learning import (
    MAX_ARROW,
    MAX_STATE_LINES,
    MIN_SIDE_RATIO,
    NEAR_STD,
    plot_demonstrations,
    plot_gmr_field,
    plot_reproductions,
    plot_state_activations,
    state_activations_title,
)
from hemg_drake.viz.figures.stability import plot_loop_stability
from hemg_drake.viz.figures.tasks import (
    ROMAN,
    mark_steps,
    plot_drawing_reproduction,
    plot_pin_reproduction,
    plot_placements,
    plot_strokes,
    steps_from_contact,
)

__all__ = [
    "MAX_ARROW", "MAX_STATE_LINES", "MIN_SIDE_RATIO", "NEAR_STD", "ROMAN", "STIFFNESS_LABEL",
    "STIFFNESS_NOTE", "STIFFNESS_UNIT", "mark_steps", "plot_demonstrations",
    "plot_drawing_reproduction", "plot_emg_envelopes", "plot_gain_law", "plot_gmr_field",
    "plot_pin_reproduction", "plot_placements", "plot_reproductions", "plot_state_activations",
    "plot_strokes", "plot_time_series", "save_figure", "state_activations_title",
    "steps_from_contact",
]  # fmt: skip

"""A sweep checked before its first trial: every trial's overrides and the metric names.

Loading a trial's scenario with its overrides costs about 10 ms, so every trial is loaded
before any runs; an unknown key or a bad value is refused in one line naming the trial, the
axis, the value and what is allowed. The metric names the sweep file asks for are checked
against the names its steps record for its task (:data:`METRICS`).
"""

from hemg_drake.yaml_schema import first_line

# The metric names each step records (trial.json, flattened with dots), common to both tasks
# and per task. ``tests/test_sweep.py`` checks them against the metrics real trials record.
_TABLE_II = [
    "table_ii.time_normalised.position_rmse_m",
    "table_ii.time_normalised.velocity_rmse_m_per_s",
    "table_ii.time_normalised.against_each_demonstration.position_rmse_m",
    "table_ii.time_normalised.against_each_demonstration.velocity_rmse_m_per_s",
    "table_ii.spatial_after_dtw.position_rmse_m",
    "table_ii.spatial_after_dtw.velocity_rmse_m_per_s",
    "table_ii.spatial_after_dtw.alignment",
    "table_ii.timing_error_s",
    *(f"table_ii.demonstrations_leave_one_out.{name}" for name in (
        "position_rmse_m", "velocity_rmse_m_per_s", "spatial_position_rmse_m",
        "spatial_velocity_rmse_m_per_s", "timing_error_s")),
    "table_ii.paper.position_rmse_m",
    "table_ii.paper.velocity_rmse_m_per_s",
    "table_ii.paper.note",
]  # fmt: skip
# analysis.interaction.interaction_metrics's record (every reproduction).
_INTERACTION = ["contact_force_peak_n", "contact_force_mean_n", "impulse_n_s", "energy_j",
                "tracking_error_rms_m", "tracking_error_max_m", "joint_torque_peak_nm",
                "block_force_peak_n", "block_impulse_n_s", "environment_force_peak_n"]  # fmt: skip
# Recorded only by a trial that has it (a push: reproduction.push): allowed in a sweep's
# metrics, not expected of every trial.
OPTIONAL = {"demonstrate": ["passivity_energy_min_j", "gave_up", "held_s", "disagreement_m",
                            "phase_lag_s", "phase_missed"],
            "reproduce": ["push.start_s", "push.release_s", "push.deviation_before_m",
                          "push.deviation_peak_m", "push.return_time_s", "push.returned"]}  # fmt: skip
METRICS = {
    "demonstrate": {
        "*": ["tracking_error_m", "master_oscillation_mm", "master_energy_peak_mj",
              "master_hit_wall", "gain_lag_s", "contact_force_peak_n", "muscle_effort",
              "hand_impulse_n_s", "hand_work_j"],
        "cotter_pin": ["pin_out", "completion_s"],
        "drawing": ["strokes", "three_strokes", "completion_s"],
    },
    "learn": {"*": ["n_iter", "converged"]},
    "reproduce": {
        "*": ["position_rmse_m", "velocity_rmse_m_per_s", "spatial_position_rmse_m",
              "timing_error_s", "stiffness_correlation", "tracking_force_peak_n",
              "tracking_force_mean_n", "peak_force_n", "success", "tracker", "weighting",
              "restoring_gain", "scene_position", "scene_yaw_deg",
              "success_checks.force within limit", "success_limits.peak_force_n", *_TABLE_II,
              "gain_source", "safe", "push", *(f"interaction.{name}" for name in _INTERACTION)],
        "cotter_pin": ["pin_out", "pin_displacement_m", "final_height_m", "peak_height_m",
                       "overshoot_m", "dip_m", "grasp_position_error_m",
                       "pull_direction_error_deg", "success_checks.pin out",
                       "success_checks.pulled along the axis", "success_checks.no overshoot",
                       "success_checks.not pushed into the fixture", "success_limits.overshoot_m",
                       "success_limits.dip_m", "success_limits.pull_direction_error_deg"],
        "drawing": ["strokes", "demonstrated_strokes", "stroke_order", "stroke_breaks",
                    "demonstrated_stroke_breaks", "stroke_shape_error_m",
                    "stroke_placement_error_m", "stiffness_on_paper", "stiffness_in_air",
                    "success_checks.three strokes", "success_checks.strokes in shape",
                    "success_checks.strokes in place", "success_limits.stroke_shape_error_m",
                    "success_limits.stroke_placement_error_m"],
    },
    "heldout": {
        "*": ["position_rmse_m", "velocity_rmse_m_per_s", "spatial_position_rmse_m",
              "spatial_velocity_rmse_m_per_s"],
    },
}  # fmt: skip
# The prefix of each step's metrics.
PREFIX = {"demonstrate": "demonstration", "learn": "learn", "reproduce": "reproduction",
          "heldout": "heldout"}  # fmt: skip


def known_metrics(tasks, steps):
    """The metric names that trials of these tasks with these steps record, in order."""
    names = []
    for step in steps:
        for group in ("*", *tasks):
            for name in METRICS[step].get(group, []):
                full = f"{PREFIX[step]}.{name}"
                if full not in names:
                    names.append(full)
    return names


def check_metrics(spec, tasks, source):
    """Raise ValueError in one line if ``spec.metrics`` names a metric no trial records."""
    known = known_metrics(tasks, spec.steps)
    optional = [f"{PREFIX[step]}.{name}" for step in spec.steps for name in OPTIONAL.get(step, [])]
    unknown = [name for name in spec.metrics if name not in known and name not in optional]
    if unknown:
        every = sorted(set(known_metrics(tasks, list(METRICS))) - set(known))
        needs = [n for n in unknown if n in every]
        hint = f" ({needs} need more steps than {list(spec.steps)})" if needs else ""
        raise ValueError(
            f"{source}: key 'metrics': unknown metric(s) {unknown}{hint}; the steps "
            f"{list(spec.steps)} of {' and '.join(tasks)} record {known}"
        )


def _parse(scenario_text, scenario_source, overrides):
    from hemg_drake.scenario import parse_scenario

    return parse_scenario(scenario_text, source=scenario_source, overrides=overrides,
                          overrides_source="override")  # fmt: skip


def check_trials(spec, all_trials, scenario_text, scenario_source, source):
    """Load every trial's scenario with its overrides; return the tasks they run.

    Raises ValueError in one line naming the sweep file, the first trial that fails, the
    axis (value or case) whose override is bad, and the scenario's own reason (the key,
    the value and what is allowed).
    """
    from hemg_drake.sweep.spec import axis_points

    tasks = []
    for trial in all_trials:
        try:
            scenario = _parse(scenario_text, scenario_source, trial.overrides)
        except ValueError as error:
            where = ""
            for axis in spec.axes:
                label = trial.labels.get(axis.name)
                if label is None:
                    continue
                point = dict(axis_points(axis))[label]
                try:
                    _parse(scenario_text, scenario_source, [*spec.set, *point])
                except ValueError as alone:
                    kind = "case" if axis.cases else "value"
                    where, error = f" (axis '{axis.name}', {kind} {label!r})", alone
                    break
            else:
                if len(trial.labels) > 1:
                    where = " (this combination of the axes' values)"
            raise ValueError(
                f"{source}: trial {trial.id}{where}: {first_line(error)}"
            ) from None
        if scenario.task not in tasks:
            tasks.append(scenario.task)
    return tasks

"""Sweeps: one scenario run many times over a grid of settings and seeds, on all cores or Ray.

A sweep file (YAML, the fields of :class:`SweepSpec`) names a base scenario, the axes to
vary, the seeds and the steps of each trial::

    scenario: cotter_pin                     # a shipped scenario, or a path (from this file)
    set: [num_demonstrations=2]              # overrides of every trial
    axes:
      - name: delay_ms                       # a column of the table, an x axis of the figure
        keys: [mapping.delay_steps, feedback.delay_steps]   # each value sets all of them
        values: [0, 50, 100]
      - name: feedback
        cases:                               # named cases, each a list of overrides
          none: [feedback.gain=0]
          force: []
    seeds: [0, 100]                          # scenario key `seed` of each trial
    steps: [demonstrate, learn, reproduce]
    metrics: [demonstration.tracking_error_m, reproduction.success]

A trial is one combination of the axes' values (``design: grid``: all combinations;
``one_at_a_time``: each axis alone, the others left at the base scenario) and one seed. It
runs in a worker process from plain data (the scenario's YAML text and the overrides: no
Drake object pickles) and writes ``OUT/trials/<id>/`` atomically (built in a temporary
folder, renamed when done): ``trial.json`` (its overrides, status, one-line error if it
failed, metrics) and ``run/``, the run folder of :mod:`hemg_drake.pipeline`. The sweep then
gathers ``OUT/results.csv`` (``results.parquet`` too if pyarrow is importable) and
``OUT/results.png`` (per metric, one line per case of the other axes against each varied
axis, the mean over seeds and its spread, +-1 standard deviation).

Demonstrations do not depend on the ``learning`` and ``reproduction`` sections, so trials
that differ only there share them: they are recorded once per seed in ``OUT/cache/``.

Before the first trial every trial's scenario is loaded with its overrides and the metric
names are checked (:mod:`~hemg_drake.sweep.checks`); the sweep then holds ``OUT`` alone
(:mod:`~hemg_drake.sweep.folder`: ``sweep.json`` marks a sweep's folder, a lock refuses a
second sweep, ``--resume`` continues only the same sweep). Ctrl-C, SIGTERM, SIGKILL or a
full disk stop the workers with the sweep and leave only finished trials.

The package's modules: :mod:`~hemg_drake.sweep.spec` (the sweep file and its trials),
:mod:`~hemg_drake.sweep.trial` (one trial in a worker, and its metrics),
:mod:`~hemg_drake.sweep.runners` (the local process pool, Ray, :func:`run_sweep`),
:mod:`~hemg_drake.sweep.results` (the table, the figure, resume bookkeeping),
:mod:`~hemg_drake.sweep.checks` (before the first trial) and :mod:`~hemg_drake.sweep.folder`
(the sweep's folder).
"""

from hemg_drake.sweep.checks import METRICS, known_metrics
from hemg_drake.sweep.folder import MARKER, sweep_folder
from hemg_drake.sweep.results import (
    finished_record,
    plot_results,
    summary,
    table_rows,
    write_results,
)
from hemg_drake.sweep.runners import (
    BACKENDS,
    RAY_OBJECT_STORE_BYTES,
    THREAD_ENV,
    Progress,
    only_loopback,
    run_sweep,
)
from hemg_drake.sweep.spec import (
    DEFAULT_METRICS,
    DESIGNS,
    STEPS,
    SWEEPS,
    Axis,
    SweepSpec,
    Trial,
    load_sweep,
    parse_sweep,
    sweep_path,
    trials,
)
from hemg_drake.sweep.trial import (
    TRIAL_FILE,
    demonstration_metrics,
    flatten,
    heldout_metrics,
    run_trial,
)

__all__ = [
    "BACKENDS", "DEFAULT_METRICS", "DESIGNS", "MARKER", "METRICS", "RAY_OBJECT_STORE_BYTES",
    "STEPS", "SWEEPS", "known_metrics", "sweep_folder",
    "THREAD_ENV", "TRIAL_FILE", "Axis", "Progress", "SweepSpec", "Trial",
    "demonstration_metrics", "finished_record", "flatten", "heldout_metrics", "load_sweep",
    "only_loopback", "parse_sweep", "plot_results", "run_sweep", "run_trial", "summary",
    "sweep_path", "table_rows", "trials", "write_results",
]  # fmt: skip

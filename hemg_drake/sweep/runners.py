"""Running a sweep's trials: a local process pool or Ray, with a progress bar."""

import contextlib
import os
import signal
import sys
import time

from hemg_drake.sweep.checks import check_metrics, check_trials
from hemg_drake.sweep.folder import sweep_folder
from hemg_drake.sweep.results import finished_record, write_results
from hemg_drake.sweep.spec import load_sweep, sweep_path, trials
from hemg_drake.sweep.trial import DISK_ERRORS, run_trial
from hemg_drake.yaml_schema import first_line

BACKENDS = ("local", "ray")
# One thread per worker: the trials are the parallelism; more threads per process would
# only contend for the same cores (numba's parallel loops, BLAS inside numpy).
THREAD_ENV = {
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
# Ray's object store: trials return a few numbers, so the smallest store Ray accepts.
RAY_OBJECT_STORE_BYTES = 80 * 1024 * 1024


class Progress:
    """A one-line progress bar on a stream: done, running, failed, time left."""

    def __init__(self, total, workers, stream=None, width=24):
        self.total, self.workers, self.width = total, workers, width
        self.stream = sys.stderr if stream is None else stream
        self.done = self.failed = self.skipped = 0
        self.began = time.perf_counter()
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def line(self):
        finished = self.done + self.failed
        remaining = self.total - finished
        running = min(self.workers, remaining)
        ran = finished - self.skipped
        elapsed = time.perf_counter() - self.began
        if ran > 0 and remaining > 0:
            left = f"{_duration(elapsed / ran * remaining)} left"
        elif remaining == 0:
            left = f"took {_duration(elapsed)}"
        else:
            left = "time left unknown"
        filled = round(self.width * finished / max(self.total, 1))
        bar = "#" * filled + "-" * (self.width - filled)
        return (f"[{bar}] {finished}/{self.total} done ({self.failed} failed), "
                f"{running} running, {left}")  # fmt: skip

    def update(self, status=None, *, skipped=False):
        if status == "done":
            self.done += 1
        elif status == "failed":
            self.failed += 1
        if skipped:
            self.skipped += 1
        end = "\r" if self.tty and self.done + self.failed < self.total else "\n"
        try:
            print(self.line(), end=end, file=self.stream, flush=True)
        except (BrokenPipeError, ValueError):
            pass


def _duration(seconds):
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}" if seconds >= 60 else f"{seconds} s"


def _task(trial, spec, text, source, out):
    return dict(
        id=trial.id, labels=trial.labels, seed=trial.seed, overrides=trial.overrides,
        reproduce_overrides=trial.reproduce_overrides, base_overrides=[*spec.set, f"seed={trial.seed}"], steps=list(spec.steps),
        heldout=spec.heldout, scenario_text=text, scenario_source=source,
        dir=str(out / "trials" / trial.id), cache=str(out / "cache"),
    )  # fmt: skip


@contextlib.contextmanager
def _thread_env():
    """THREAD_ENV in os.environ while workers start (they inherit it), restored after."""
    saved = {name: os.environ.get(name) for name in THREAD_ENV}
    os.environ.update(THREAD_ENV)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _worker_init(parent):
    """In each worker: die with the sweep (SIGKILL when the parent process ends, however it
    ends: Linux ``PR_SET_PDEATHSIG``), and leave Ctrl-C to the parent (a terminal sends it
    to the whole process group; the parent stops the workers and tidies their folders)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with contextlib.suppress(OSError, AttributeError):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the parent ended before the line above
        os._exit(1)


_PR_SET_PDEATHSIG = 1


def _stop_workers(pool):
    """Kill a process pool's workers at once (their running trials are abandoned) and wait
    for them to end."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for process in processes:
        with contextlib.suppress(Exception):
            process.kill()
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(timeout=5)
    pool.shutdown(wait=False, cancel_futures=True)


def _run_local(tasks, workers, on_record):
    import concurrent.futures as cf
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=context,
                                  initializer=_worker_init, initargs=(os.getpid(),))  # fmt: skip
    try:
        with _thread_env():
            futures = {pool.submit(run_trial, task): task for task in tasks}
        for future in cf.as_completed(futures):
            try:
                record = future.result()
            except OSError as error:
                if error.errno in DISK_ERRORS:
                    raise  # the disk, not the trial: stop the sweep
                record = _crashed(futures[future], error)
            except Exception as error:  # noqa: BLE001 - a worker died
                record = _crashed(futures[future], error)
            on_record(record)
    except BaseException:
        _stop_workers(pool)
        raise
    pool.shutdown(wait=True)


def _crashed(task, error):
    return dict(id=task["id"], labels=task["labels"], seed=task["seed"],
                overrides=task["overrides"], status="failed", metrics={}, elapsed_s=0.0,
                error=f"worker died: {type(error).__name__}: {first_line(error)}")  # fmt: skip


def only_loopback():
    """True if this process's network interfaces are just ``lo`` (a loopback-only network
    namespace); ``socket.if_nameindex`` asks the kernel for this process's namespace."""
    import socket

    try:
        return [name for _, name in socket.if_nameindex()] == ["lo"]
    except OSError:
        return False


def _run_ray(tasks, workers, address, on_record):
    try:
        import ray
    except ImportError:
        raise ValueError(
            "--backend ray needs Ray: pip install 'hemg-drake[ray]' (or pip install ray)"
        ) from None
    runtime_env = {"env_vars": dict(THREAD_ENV)}
    if address:
        ray.init(address=address, runtime_env=runtime_env, log_to_driver=False)
    else:
        # Ray binds the machine's own address whatever _node_ip_address says (measured with
        # Ray 2.60): start a local instance only where the loopback is the only network.
        if not only_loopback():
            raise ValueError(
                "--backend ray without --address starts a local Ray, which binds this "
                "machine's network address; run it in a loopback-only network namespace "
                "(as root: unshare -n, then ip link set lo up), or join a cluster with "
                "--address, or use the local backend (the default)"
            )
        # A private local instance, without the dashboard.
        ray.init(
            _node_ip_address="127.0.0.1", include_dashboard=False, num_cpus=workers,
            object_store_memory=RAY_OBJECT_STORE_BYTES, runtime_env=runtime_env,
            log_to_driver=False,
        )  # fmt: skip
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        pending = {remote.remote(task): task for task in tasks}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                task = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except OSError as error:
                    if error.errno in DISK_ERRORS:
                        raise
                    record = _crashed(task, error)
                except Exception as error:  # noqa: BLE001 - the task's worker died
                    record = _crashed(task, error)
                on_record(record)
    except BaseException:
        for ref in pending:  # stop the running trials with the sweep (force: kill them)
            with contextlib.suppress(Exception):
                ray.cancel(ref, force=True)
        raise
    finally:
        ray.shutdown()


def run_sweep(path, out, *, backend="local", workers=None, address=None, resume=False,
              stream=None):  # fmt: skip
    """Run a sweep file's trials into ``out``; write the table and the figure.

    Parameters
    ----------
    path : path-like, the sweep file.
    out : path-like, the sweep's folder (created).
    backend : {"local", "ray"}
        "local": a process pool on this machine; "ray": one Ray task per trial
        (``address`` joins a cluster; none starts a local instance on 127.0.0.1).
    workers : int, optional
        Processes (local) or CPUs of the local Ray instance; default all cores.
    resume : bool
        Skip the trials already done in ``out`` (failed ones run again); only in a folder
        that the same sweep wrote (:mod:`~hemg_drake.sweep.folder`). Without it, a folder
        that holds trials is refused.
    stream : file, the progress bar's (default stderr).

    Every trial's overrides and the metric names are checked first (ValueError in one
    line); the folder is then held (:func:`~hemg_drake.sweep.folder.sweep_folder`: a
    second sweep on it is refused). Interrupted (Ctrl-C, SIGTERM) or stopped by a full
    disk, the workers are killed and no unfinished trial's folder remains.

    Returns
    -------
    list of dict, the trials' records, in the sweep's order.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    spec, text, source = load_sweep(path)
    spec_text = sweep_path(path).read_text(encoding="utf-8")
    all_trials = trials(spec)
    # Every trial's scenario and the metric names, before anything is written.
    tasks_run = check_trials(spec, all_trials, text, source, str(sweep_path(path)))
    check_metrics(spec, tasks_run, str(sweep_path(path)))
    with sweep_folder(out, spec, text, spec_text, resume=resume) as out:
        records = {}
        for trial in all_trials:
            record = finished_record(out, trial) if resume else None
            if record is not None:
                records[trial.id] = record
        todo = [t for t in all_trials if t.id not in records]
        progress = Progress(len(all_trials), min(workers, max(len(todo), 1)), stream)
        # Trials done in an earlier run count as done, not in the time left.
        progress.done = progress.skipped = len(records)
        progress.update()

        def on_record(record):
            records[record["id"]] = record
            progress.update(record["status"])

        tasks = [_task(t, spec, text, source, out) for t in todo]
        if tasks:
            if backend == "local":
                _run_local(tasks, workers, on_record)
            else:
                _run_ray(tasks, workers, address, on_record)
        ordered = [records[t.id] for t in all_trials]
        write_results(ordered, spec, out)
    return ordered

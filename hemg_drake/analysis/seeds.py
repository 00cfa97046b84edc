"""The tuning and evaluation seeds (``hemg_drake/data/seeds.yaml``), and the refusals.

Settings are chosen on tuning seeds only; figures are reported on evaluation seeds, which
no setting saw. A run with scenario seed s and C demonstrations uses seeds s .. s + C - 1;
its fresh demonstrations (scored out of sample) t .. t + C_test - 1.
"""

import functools
import importlib.resources

import yaml

SEEDS_FILE = importlib.resources.files("hemg_drake") / "data" / "seeds.yaml"
KINDS = ("tuning", "evaluation")


@functools.cache
def seed_sets():
    """The file's contents: ``{"tuning": {"ranges", "runs"}, "evaluation": {"runs", "demo"}}``
    (runs: task -> list of (training seed, first fresh seed))."""
    data = yaml.safe_load(SEEDS_FILE.read_text())
    for task, runs in {**data["tuning"]["runs"], **data["evaluation"]["runs"]}.items():
        if not all(len(pair) == 2 for pair in runs):
            raise ValueError(f"{SEEDS_FILE}: runs of {task} must be [training, fresh] pairs")
    return data


def is_tuning(seed):
    """True if ``seed`` lies in a tuning range of the seeds file."""
    return any(first <= seed <= last for first, last in seed_sets()["tuning"]["ranges"])


def check_seeds(seeds, kind, *, what="seeds"):
    """Refuse, in one line, a tuning seed where evaluation seeds are asked for (or an
    evaluation seed, one outside every tuning range, where tuning seeds are).

    Parameters
    ----------
    seeds : iterable of int, every demonstration seed a run would use.
    kind : {"tuning", "evaluation"}
    what : str, what the seeds are (named in the message).

    Raises
    ------
    ValueError
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    seeds = sorted(set(int(s) for s in seeds))
    wrong = [s for s in seeds if is_tuning(s) != (kind == "tuning")]
    if wrong:
        ranges = ", ".join(f"{a}-{b}" for a, b in seed_sets()["tuning"]["ranges"])
        said = "a tuning seed" if kind == "evaluation" else "not a tuning seed"
        raise ValueError(
            f"{what}: seed {wrong[0]} is {said} ({SEEDS_FILE.name}: tuning seeds {ranges}); "
            + ("settings were chosen on it, so it cannot evaluate them"
               if kind == "evaluation" else "an evaluation seed must not choose a setting")
        )  # fmt: skip
    return seeds


def run_seeds(seed, count):
    """The demonstration seeds of a run: ``seed .. seed + count - 1``."""
    return list(range(int(seed), int(seed) + int(count)))

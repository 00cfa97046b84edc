"""Where the project's model files are (``models/``): found without pydrake.

The Baxter arm (:mod:`hemg_drake.robots.baxter`) and the task scenes load them into a
plant; the task plans (:mod:`hemg_drake.tasks.plans`) read a length from them as XML.
"""

import importlib.resources
from pathlib import Path


def find_models_dir(candidates=None):
    """The project's ``models/`` folder: the first candidate that holds its ``package.xml``.

    By default: the package's own ``hemg_drake/models`` (package data in any install, found
    with ``importlib.resources``; in a checkout a link to the repository's ``models/``), then
    ``models/`` beside the package. If neither holds the models, the first candidate is
    returned and loading a model raises ``FileNotFoundError`` naming the missing file.
    """
    if candidates is None:
        candidates = (
            Path(str(importlib.resources.files("hemg_drake") / "models")),
            Path(__file__).resolve().parents[1] / "models",
        )
    candidates = [Path(candidate) for candidate in candidates]
    for candidate in candidates:
        if (candidate / "package.xml").is_file():
            return candidate
    return candidates[0]


MODELS_DIR = find_models_dir()

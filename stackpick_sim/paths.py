"""Where the package finds its MJCF models and scene configs.

In a source checkout (and an editable install) they are the repository's top-level
``models/`` and ``scenes/``; in an installed wheel they are carried inside the package
(see ``[tool.hatch.build.targets.wheel.force-include]`` in pyproject.toml).
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def _data_dir(name: str) -> Path:
    inside = _PACKAGE / name
    return inside if inside.is_dir() else _PACKAGE.parent / name


MODELS_DIR: Path = _data_dir("models")
SCENES_DIR: Path = _data_dir("scenes")


def model_path(name: str) -> Path:
    """Path of ``models/<name>/<name>.xml``."""
    return MODELS_DIR / name / f"{name}.xml"

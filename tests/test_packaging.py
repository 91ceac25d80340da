"""The wheel carries the models and scenes, so an installed stackpick finds them."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

from stackpick_sim.paths import MODELS_DIR, SCENES_DIR

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_contains_models_scenes_and_py_typed(tmp_path: Path) -> None:
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps",
                    "--no-build-isolation", "--wheel-dir", str(tmp_path), str(ROOT)],
                   check=True, capture_output=True)
    (wheel,) = tmp_path.glob("stackpick_sim-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {f"stackpick_sim/models/{p.relative_to(MODELS_DIR).as_posix()}"
                for p in MODELS_DIR.rglob("*") if p.is_file()}
    expected |= {f"stackpick_sim/scenes/{p.name}" for p in SCENES_DIR.glob("*.toml")}
    expected.add("stackpick_sim/py.typed")
    assert expected <= names, sorted(expected - names)

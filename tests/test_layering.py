"""Package layering: stackpick_sim.runs depends on stackpick_sim.episodes, never the reverse."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import stackpick_sim

EPISODES = Path(stackpick_sim.__file__).parent / "episodes"


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


def test_episodes_never_import_runs() -> None:
    offending = {p.name: sorted(n for n in _imports(p) if n.startswith("stackpick_sim.runs"))
                 for p in sorted(EPISODES.glob("*.py"))}
    assert not {k: v for k, v in offending.items() if v}


def test_importing_episodes_loads_no_runs_module() -> None:
    code = ("import sys, stackpick_sim.episodes; "
            "print(sorted(m for m in sys.modules if m.startswith('stackpick_sim.runs')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"

"""Reading the JSON files of run and sweep directories: one clear error for any bad bytes."""

from __future__ import annotations

import json
from pathlib import Path

from stackpick_sim.exceptions import StackpickError


def read_json(path: Path, what: str, error: type[StackpickError] = StackpickError) -> object:
    """The JSON value in ``path``; ``error`` naming the file and ``what`` it should be when
    the bytes are not UTF-8 JSON (including nesting too deep to parse)."""
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise error(f"{path} is not UTF-8 text, so not {what}") from None
    except RecursionError:
        raise error(f"{path} nests arrays or objects too deeply to read, so is not {what}"
                    ) from None
    except ValueError as exc:  # JSONDecodeError
        raise error(f"{path} is not JSON ({exc}), so not {what}") from None

"""Is offscreen OpenGL rendering available? One line saying what to install when it is not.

This module imports MuJoCo lazily: with a broken GL backend ``import mujoco`` itself fails
(it loads the backend named by ``MUJOCO_GL`` at import time), and that failure is what we
must report. ``python -m stackpick_sim.glcheck`` is the Makefile's ``gl-check``.
"""

from __future__ import annotations

import os
import sys

#: Debian packages that provide EGL through Mesa on a machine without a GPU.
EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"


def gl_failure_message(exc: BaseException) -> str:
    """One line: what failed and which system packages to install."""
    import stackpick_sim

    if stackpick_sim.MUJOCO_IMPORTED_FIRST:
        return (f"offscreen rendering failed ({type(exc).__name__}: {exc}); mujoco was imported "
                "before stackpick_sim with MUJOCO_GL unset, so it chose a windowed backend: set "
                "MUJOCO_GL=egl in the environment or import stackpick_sim first")
    backend = os.environ.get("MUJOCO_GL", "")
    hint = (f"install the Debian packages: apt-get install -y {EGL_PACKAGES} (or: make system-deps)"
            if backend == "egl" else "set MUJOCO_GL=egl on a headless machine")
    return (f"offscreen rendering with MUJOCO_GL={backend} failed "
            f"({type(exc).__name__}: {exc}); {hint}")


def check_rendering() -> str | None:
    """None if a 16x16 offscreen frame renders here, else one line saying what to install."""
    try:
        import mujoco

        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        renderer = mujoco.Renderer(model, 16, 16)
        renderer.render()
        renderer.close()
    except Exception as exc:  # any failure of the GL stack, whatever MuJoCo raises for it
        return gl_failure_message(exc)
    return None


if __name__ == "__main__":
    os.environ.setdefault("MUJOCO_GL", "egl")
    problem = check_rendering()
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        sys.exit(1)

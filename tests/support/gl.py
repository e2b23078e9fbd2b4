"""A headless OpenGL 3.3 context (pyglet's EGL mode with Mesa) for the rendering tests: where it
cannot be made they skip, saying what to install, or fail when ECS_ANIM_REQUIRE_GL is set (CI)."""

from __future__ import annotations

import os
import subprocess
import sys
from functools import cache

import pytest


@cache
def headless_gl() -> str | None:
    """None if a headless OpenGL 3.3 context can be made, else why not (in a subprocess, so a
    crashing driver cannot take the test run with it)."""
    code = ("import pyglet; pyglet.options['headless'] = True; pyglet.options['shadow_window'] = False\n"
            "from ecs_anim.apps.viewer.gl_setup import load_pyglet as _pyglet, make_window as _make_window\n"
            "w = _make_window(_pyglet(True), 16, 16, visible=False); print('ok'); w.close()")
    try:
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             timeout=60, check=False)
    except subprocess.TimeoutExpired:
        return "making a headless OpenGL context timed out"
    if out.returncode == 0 and "ok" in out.stdout:
        return None
    last = (out.stderr.strip().splitlines() or ["no output"])[-1]
    return (f"no headless OpenGL 3.3 (EGL) here: {last}. Install Debian's libegl1 and "
            "libgl1-mesa-dri (.ci/run does)")


def need_gl() -> None:
    """Skip the calling test where :func:`headless_gl` gives a reason (fail with
    ECS_ANIM_REQUIRE_GL set, as CI sets it)."""
    reason = headless_gl()
    if reason is not None:
        if os.environ.get("ECS_ANIM_REQUIRE_GL"):
            pytest.fail(reason)
        pytest.skip(reason)

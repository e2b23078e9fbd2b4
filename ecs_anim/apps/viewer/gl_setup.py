"""The GL setup the window and screenshots share: pyglet loaded headless (EGL) or not, a window
with an OpenGL 3.3 core context, a text label, and forked children kept off the parent's display."""

from __future__ import annotations

import os
import sys
from typing import Any

from ecs_anim.core.errors import EcsAnimError

#: What to install where OpenGL cannot be loaded, ending such errors.
INSTALL_HINT = ("on Debian/Ubuntu install libegl1 and libgl1-mesa-dri (headless EGL), "
                "or run under xvfb-run (package xvfb)")


def _keep_gl_out_of_forked_children() -> None:
    """In a process forked from this one, pyglet's headless display must not be torn down: its
    finaliser calls ``eglTerminate`` on the parent's EGL connection, which deadlocks in the
    child (the driver's threads were not forked), as a batch worker collecting garbage left by
    an earlier screenshot did. The display belongs to the parent, which ends it itself."""
    headless = sys.modules.get("pyglet.display.headless")
    if headless is not None:
        headless.HeadlessDisplay.__del__ = _no_finaliser


def _no_finaliser(self: object) -> None:
    """A forked child's stand-in for pyglet's ``HeadlessDisplay.__del__``."""


_FORK_HOOK: list[bool] = []  # registered once per process, when drawing first loads pyglet


def load_pyglet(headless: bool) -> Any:
    """Import pyglet for drawing, headless (EGL, no screen) or not. One-line errors."""
    if not _FORK_HOOK:
        os.register_at_fork(after_in_child=_keep_gl_out_of_forked_children)
        _FORK_HOOK.append(True)
    try:
        import pyglet
    except ImportError as exc:  # pragma: no cover - a dependency
        raise EcsAnimError(f"pyglet is not installed ({exc}); pip install 'pyglet>=2,<3'") from None
    if "pyglet.window" not in sys.modules:  # the mode is fixed once pyglet.window is imported
        pyglet.options["headless"] = headless
        pyglet.options["shadow_window"] = False
    try:
        import pyglet.window
        from pyglet import gl  # noqa: F401
    except Exception as exc:
        raise EcsAnimError(f"cannot load OpenGL ({type(exc).__name__}: {exc}); {INSTALL_HINT}") from None
    return pyglet


def _gl_config(pyglet: Any, samples: int) -> list[Any]:
    gl = pyglet.gl
    extra = {"sample_buffers": 1, "samples": samples} if samples else {}
    return [gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24,
                      double_buffer=True, **extra),
            gl.Config(major_version=3, minor_version=3, forward_compatible=True, depth_size=24),
            None]


def make_window(pyglet: Any, width: int, height: int, visible: bool, samples: int = 0,
                cls: type | None = None, **kwargs: Any) -> Any:
    """A window with an OpenGL >= 3.3 core context; the first config that works."""
    window_cls = cls or pyglet.window.Window
    last: Exception | None = None
    for config in _gl_config(pyglet, samples):
        try:
            window = window_cls(width=width, height=height, visible=visible, config=config, **kwargs)
        except Exception as exc:
            last = exc
            continue
        version = tuple(int(v) for v in pyglet.gl.gl_info.get_version()[:2])
        if version < (3, 3):
            window.close()
            raise EcsAnimError(f"OpenGL 3.3 is needed, this context offers {version[0]}.{version[1]} "
                               f"({pyglet.gl.gl_info.get_renderer()}); {INSTALL_HINT}")
        return window
    raise EcsAnimError(f"cannot open an OpenGL 3.3 context ({type(last).__name__}: "
                       f"{str(last).strip() or 'no details'}); {INSTALL_HINT}")


def text_label(pyglet: Any, text: str, x: float, y: float, size: float) -> Any:
    """A dark label whose top-left corner is at (``x``, ``y``) pixels, ``size`` points."""
    return pyglet.text.Label(text, x=x, y=y, anchor_x="left", anchor_y="top", font_size=size,
                             color=(25, 25, 30, 255))

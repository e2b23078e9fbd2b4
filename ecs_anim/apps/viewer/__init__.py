"""The viewer (scenario issue, part 4): pyglet 2 / OpenGL 3.3 drawing of a running scenario.

``camera`` and ``scene`` are pure numpy (testable without a screen); ``gl_setup``,
``gl_render``, ``screenshot`` and ``window`` need pyglet and an OpenGL context (a window, or
headless EGL for screenshots).
Rendering only reads the simulation (STYLE 8).
"""

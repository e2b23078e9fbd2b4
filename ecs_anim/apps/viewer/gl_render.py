"""OpenGL 3.3 core drawing of a :class:`~ecs_anim.apps.viewer.scene.SceneFrame` (pyglet 2).

Three programs: the ground (a height-field mesh with a 1 m checker, lit), capsule instances
(every body part, target, centre of mass and restricted area of every character: one
``glDrawElementsInstanced`` call for the opaque ones, one for the x-ray centres of mass and one
for translucent areas), and pyglet's own text for the status line. Needs a current GL context.
"""

from __future__ import annotations

import ctypes
import math

import numpy as np
from numpy.typing import NDArray
from pyglet import gl
from pyglet.graphics.shader import Shader, ShaderProgram

from ecs_anim.apps.viewer.camera import OrbitCamera
from ecs_anim.apps.viewer.scene import INSTANCE_FLOATS, GroundMesh, SceneFrame

SKY = (0.82, 0.84, 0.86)
#: Width of the band where the near and far ground patches overlap, and how much lower the far
#: one is drawn there (metres).
GROUND_OVERLAP_M, GROUND_SINK_M = 0.5, 0.04
#: Above this many capsule instances in one draw, the coarse capsule mesh is used.
FINE_CAPSULES_UP_TO = 4000

_CAPSULE_VS = """
#version 330 core
layout(location = 0) in vec3 unit_point;   // on the unit sphere, capsule axis = +z
layout(location = 1) in float at_b;        // 0: the cap around a, 1: the cap around b
layout(location = 2) in vec3 a;
layout(location = 3) in vec3 b;
layout(location = 4) in float radius;
layout(location = 5) in vec4 colour;
uniform mat4 world2clip;
out vec3 v_normal;
out vec3 v_world;
out vec4 v_colour;
void main() {
    vec3 axis = b - a;
    float len = length(axis);
    vec3 z = len > 1e-6 ? axis / len : vec3(0.0, 0.0, 1.0);
    vec3 helper = abs(z.z) < 0.9 ? vec3(0.0, 0.0, 1.0) : vec3(1.0, 0.0, 0.0);
    vec3 x = normalize(cross(helper, z));
    vec3 y = cross(z, x);
    vec3 n = x * unit_point.x + y * unit_point.y + z * unit_point.z;
    v_world = mix(a, b, at_b) + radius * n;
    v_normal = n;
    v_colour = colour;
    gl_Position = world2clip * vec4(v_world, 1.0);
}
"""

_LIGHTING = """
uniform vec3 eye;
uniform vec3 sky;
uniform vec2 fog_range;
vec3 shade(vec3 base, vec3 normal, vec3 world) {
    vec3 n = normalize(normal);
    vec3 key = normalize(vec3(0.45, -0.35, 0.82));
    vec3 fill = normalize(vec3(-0.6, 0.7, 0.35));
    vec3 view = normalize(eye - world);
    float diffuse = max(dot(n, key), 0.0) * 0.75 + max(dot(n, fill), 0.0) * 0.25;
    float hemi = 0.5 + 0.5 * n.z;
    vec3 colour = base * (0.28 + 0.22 * hemi + diffuse * 0.7);
    float spec = pow(max(dot(reflect(-key, n), view), 0.0), 24.0) * 0.18;
    return colour + vec3(spec);
}
vec3 fog(vec3 colour, vec3 world) {
    float d = length(eye - world);
    float f = clamp((d - fog_range.x) / (fog_range.y - fog_range.x), 0.0, 1.0);
    return mix(colour, sky, f);
}
"""

_CAPSULE_FS = """
#version 330 core
in vec3 v_normal;
in vec3 v_world;
in vec4 v_colour;
out vec4 frag;
""" + _LIGHTING + """
void main() {
    frag = vec4(fog(shade(v_colour.rgb, v_normal, v_world), v_world), v_colour.a);
}
"""

_GROUND_VS = """
#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
uniform mat4 world2clip;
uniform float sink;  // the far patch sits this much lower, under the near one where they overlap
out vec3 v_normal;
out vec3 v_world;
void main() {
    v_world = position - vec3(0.0, 0.0, sink);
    v_normal = normal;
    gl_Position = world2clip * vec4(position, 1.0);
}
"""

_GROUND_FS = """
#version 330 core
in vec3 v_normal;
in vec3 v_world;
out vec4 frag;
uniform vec4 hole;  // x0, y0, x1, y1: not drawn inside (where the finer patch is)
""" + _LIGHTING + """
void main() {
    if (all(greaterThan(v_world.xy, hole.xy)) && all(lessThan(v_world.xy, hole.zw))) discard;
    vec2 cell = floor(v_world.xy);
    float checker = mod(cell.x + cell.y, 2.0);
    // far away a metre covers less than a pixel or two: fade the pattern to its mean (no moire)
    float blur = clamp(max(fwidth(v_world.x), fwidth(v_world.y)) * 1.5 - 0.25, 0.0, 1.0);
    checker = mix(checker, 0.5, blur);
    vec3 base = mix(vec3(0.62, 0.62, 0.60), vec3(0.52, 0.53, 0.52), checker);
    vec2 f = abs(fract(v_world.xy + 0.5) - 0.5);
    float line = 1.0 - smoothstep(0.0, 0.012, min(f.x, f.y));
    base = mix(base, vec3(0.42), line * 0.6 * (1.0 - blur));
    frag = vec4(fog(shade(base, v_normal, v_world), v_world), 1.0);
}
"""


def capsule_mesh(segments: int = 16, rings: int = 6) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """A unit sphere split at its equator into two caps (vertices (k, 4): unit point, at_b).

    Vertices with z >= 0 belong to the cap around b, z < 0 to the one around a; the equator is
    doubled so the band between the caps becomes the capsule's cylinder.
    """
    rows = []
    # latitude from south pole (-90°) to north pole (+90°): rings per cap + the doubled equator
    lat_a = np.linspace(-math.pi / 2, 0.0, rings + 1)
    lat_b = np.linspace(0.0, math.pi / 2, rings + 1)
    lats = [(t, 0.0) for t in lat_a] + [(t, 1.0) for t in lat_b]
    lon = np.linspace(0.0, 2 * math.pi, segments + 1)
    for lat, at_b in lats:
        c, s = math.cos(lat), math.sin(lat)
        rows.append(np.stack([c * np.cos(lon), c * np.sin(lon), np.full_like(lon, s),
                              np.full_like(lon, at_b)], axis=1))
    vertices = np.concatenate(rows).astype(np.float32)
    width = segments + 1
    tris = []
    for r in range(len(lats) - 1):
        for k in range(segments):
            v0 = r * width + k
            v1, v2, v3 = v0 + 1, v0 + width, v0 + width + 1
            tris += [(v0, v1, v3), (v0, v3, v2)]
    return vertices, np.array(tris, dtype=np.uint32)


def _buffer(target: int, data: np.ndarray, usage: int = gl.GL_STATIC_DRAW) -> gl.GLuint:
    handle = gl.GLuint()
    gl.glGenBuffers(1, ctypes.byref(handle))
    gl.glBindBuffer(target, handle)
    gl.glBufferData(target, data.nbytes, data.ctypes.data_as(ctypes.c_void_p), usage)
    return handle


def _attribute(location: int, size: int, stride_floats: int, offset_floats: int,
               divisor: int = 0) -> None:
    gl.glEnableVertexAttribArray(location)
    gl.glVertexAttribPointer(location, size, gl.GL_FLOAT, gl.GL_FALSE, stride_floats * 4,
                             ctypes.c_void_p(offset_floats * 4))
    if divisor:
        gl.glVertexAttribDivisor(location, divisor)


def _matrix(m: np.ndarray) -> tuple[float, ...]:
    """A numpy (4, 4) as the column-major tuple GL wants."""
    return tuple(float(v) for v in np.asarray(m).T.reshape(-1))


class SceneRenderer:
    """GL resources for drawing frames: made once per context, :meth:`draw` per frame."""

    def __init__(self) -> None:
        self.capsules = ShaderProgram(Shader(_CAPSULE_VS, "vertex"), Shader(_CAPSULE_FS, "fragment"))
        self.ground = ShaderProgram(Shader(_GROUND_VS, "vertex"), Shader(_GROUND_FS, "fragment"))
        self.instance_vbo = _buffer(gl.GL_ARRAY_BUFFER, np.zeros((1, INSTANCE_FLOATS), np.float32),
                                    gl.GL_STREAM_DRAW)
        # Two levels of detail sharing the instance buffer: fine capsules for a few characters,
        # coarse ones when there are many (a crowd is small on screen anyway).
        self.meshes = [self._capsule_vao(*capsule_mesh(16, 6)), self._capsule_vao(*capsule_mesh(8, 3))]
        self._keep: list[gl.GLuint] = []
        self._grounds: list[tuple[gl.GLuint, list[gl.GLuint], int]] = []
        self.ground_bounds: list[tuple[float, float, float, float]] = []

    def _capsule_vao(self, vertices: np.ndarray, triangles: np.ndarray) -> tuple[gl.GLuint, int]:
        vao = gl.GLuint()
        gl.glGenVertexArrays(1, ctypes.byref(vao))
        gl.glBindVertexArray(vao)
        _buffer(gl.GL_ARRAY_BUFFER, vertices)
        _attribute(0, 3, 4, 0)
        _attribute(1, 1, 4, 3)
        _buffer(gl.GL_ELEMENT_ARRAY_BUFFER, triangles)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, self.instance_vbo)
        for location, size, offset in ((2, 3, 0), (3, 3, 3), (4, 1, 6), (5, 4, 7)):
            _attribute(location, size, INSTANCE_FLOATS, offset, divisor=1)
        gl.glBindVertexArray(0)
        return vao, int(triangles.size)

    def set_ground(self, near: GroundMesh, far: GroundMesh | None = None) -> None:
        """Upload the ground (replacing the previous one): a fine ``near`` patch, and a coarse
        ``far`` one drawn only outside the near one's rectangle."""
        for vao, buffers, _ in self._grounds:
            gl.glDeleteVertexArrays(1, ctypes.byref(vao))
            for b in buffers:
                gl.glDeleteBuffers(1, ctypes.byref(b))
        self._grounds, self.ground_bounds = [], []
        for mesh in (near, far):
            if mesh is None:
                continue
            vao = gl.GLuint()
            gl.glGenVertexArrays(1, ctypes.byref(vao))
            gl.glBindVertexArray(vao)
            buffers = [_buffer(gl.GL_ARRAY_BUFFER, mesh.vertices)]
            _attribute(0, 3, 6, 0)
            _attribute(1, 3, 6, 3)
            buffers.append(_buffer(gl.GL_ELEMENT_ARRAY_BUFFER, mesh.triangles))
            gl.glBindVertexArray(0)
            self._grounds.append((vao, buffers, int(mesh.triangles.size)))
            self.ground_bounds.append(mesh.bounds)

    def _common(self, program: ShaderProgram, world2clip: np.ndarray, camera: OrbitCamera) -> None:
        program.use()
        program["world2clip"] = _matrix(world2clip)
        program["eye"] = tuple(float(v) for v in camera.eye)
        program["sky"] = SKY
        program["fog_range"] = (camera.distance * 1.5, camera.distance * 3.0 + 10.0)

    def _instances(self, rows: np.ndarray) -> None:
        rows = np.ascontiguousarray(rows, dtype=np.float32)
        vao, count = self.meshes[0 if rows.shape[0] <= FINE_CAPSULES_UP_TO else 1]
        gl.glBindVertexArray(vao)
        gl.glBindBuffer(gl.GL_ARRAY_BUFFER, self.instance_vbo)
        gl.glBufferData(gl.GL_ARRAY_BUFFER, rows.nbytes, rows.ctypes.data_as(ctypes.c_void_p),
                        gl.GL_STREAM_DRAW)
        gl.glDrawElementsInstanced(gl.GL_TRIANGLES, count, gl.GL_UNSIGNED_INT,
                                   ctypes.c_void_p(0), rows.shape[0])

    def draw(self, frame: SceneFrame, camera: OrbitCamera, width: int, height: int,
             show_targets: bool = True, show_com: bool = True) -> None:
        """Clear and draw the frame into the current framebuffer's (0, 0, width, height)."""
        gl.glViewport(0, 0, width, height)
        gl.glClearColor(*SKY, 1.0)
        gl.glClear(gl.GL_COLOR_BUFFER_BIT | gl.GL_DEPTH_BUFFER_BIT)
        gl.glEnable(gl.GL_DEPTH_TEST)
        gl.glDepthFunc(gl.GL_LESS)
        gl.glEnable(gl.GL_CULL_FACE)
        gl.glCullFace(gl.GL_BACK)
        gl.glFrontFace(gl.GL_CCW)
        world2clip = camera.world2clip(width, height)
        if self._grounds:
            gl.glDisable(gl.GL_CULL_FACE)
            self._common(self.ground, world2clip, camera)
            for k, (vao, _, count) in enumerate(self._grounds):
                # the far patch leaves out the near patch's rectangle, less a band where both
                # are drawn (the far one a little lower), so no crack opens between them
                x0, y0, x1, y1 = self.ground_bounds[0]
                band = GROUND_OVERLAP_M
                self.ground["hole"] = (x0 + band, y0 + band, x1 - band, y1 - band) if k else (0.0,) * 4
                self.ground["sink"] = GROUND_SINK_M if k else 0.0
                gl.glBindVertexArray(vao)
                gl.glDrawElements(gl.GL_TRIANGLES, count, gl.GL_UNSIGNED_INT, ctypes.c_void_p(0))
            gl.glEnable(gl.GL_CULL_FACE)
        self._common(self.capsules, world2clip, camera)
        opaque = [frame.bodies, frame.props] + ([frame.targets] if show_targets else [])
        rows = np.concatenate(opaque)
        if rows.shape[0]:
            self._instances(rows)
        gl.glEnable(gl.GL_BLEND)
        gl.glBlendFunc(gl.GL_SRC_ALPHA, gl.GL_ONE_MINUS_SRC_ALPHA)
        if show_com and frame.com.shape[0]:
            # x-ray: the centre of mass lies inside the body; draw it over everything.
            gl.glDisable(gl.GL_DEPTH_TEST)
            self._instances(frame.com)
            gl.glEnable(gl.GL_DEPTH_TEST)
        if show_targets and frame.areas.shape[0]:
            gl.glDepthMask(gl.GL_FALSE)
            self._instances(frame.areas)
            gl.glDepthMask(gl.GL_TRUE)
        gl.glDisable(gl.GL_BLEND)
        gl.glBindVertexArray(0)
        self.capsules.stop()
        gl.glDisable(gl.GL_CULL_FACE)
        gl.glDisable(gl.GL_DEPTH_TEST)


class OffscreenTarget:
    """A framebuffer object (colour + depth renderbuffers) to render a screenshot into."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.fbo = gl.GLuint()
        gl.glGenFramebuffers(1, ctypes.byref(self.fbo))
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self.fbo)
        self.colour, self.depth = gl.GLuint(), gl.GLuint()
        for handle, fmt, attachment in ((self.colour, gl.GL_RGBA8, gl.GL_COLOR_ATTACHMENT0),
                                        (self.depth, gl.GL_DEPTH_COMPONENT24, gl.GL_DEPTH_ATTACHMENT)):
            gl.glGenRenderbuffers(1, ctypes.byref(handle))
            gl.glBindRenderbuffer(gl.GL_RENDERBUFFER, handle)
            gl.glRenderbufferStorage(gl.GL_RENDERBUFFER, fmt, width, height)
            gl.glFramebufferRenderbuffer(gl.GL_FRAMEBUFFER, attachment, gl.GL_RENDERBUFFER, handle)
        status = gl.glCheckFramebufferStatus(gl.GL_FRAMEBUFFER)
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, 0)
        if status != gl.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"offscreen framebuffer {width}x{height} incomplete (0x{status:x})")

    def bind(self) -> None:
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self.fbo)

    def read_rgb(self) -> NDArray[np.uint8]:
        """(height, width, 3) uint8, first row at the top of the image."""
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, self.fbo)
        gl.glPixelStorei(gl.GL_PACK_ALIGNMENT, 1)
        out = np.empty((self.height, self.width, 4), np.uint8)
        gl.glReadPixels(0, 0, self.width, self.height, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE,
                        out.ctypes.data_as(ctypes.c_void_p))
        return np.ascontiguousarray(out[::-1, :, :3])

    def release(self) -> None:
        gl.glBindFramebuffer(gl.GL_FRAMEBUFFER, 0)
        gl.glDeleteFramebuffers(1, ctypes.byref(self.fbo))
        gl.glDeleteRenderbuffers(1, ctypes.byref(self.colour))
        gl.glDeleteRenderbuffers(1, ctypes.byref(self.depth))

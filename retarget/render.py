"""Offscreen rendering of meshes (moderngl, EGL standalone context, no window).

Used for the frontal image the CNN reads (the image code c of NFS), and for PNG previews.

Camera: orthographic, looking along −z at the face (the face looks along +z, +y is up), so the
character's left (+x) appears on the image's right. With ``fit=True`` the camera frames the mesh's
bounding box (centred, fixed 5 % margin, aspect kept), so the image does not depend on the mesh's
scale or translation. Depth test is on and faces are lit two-sided (meshes are open at the neck, eyes
and mouth, and user meshes may have inconsistent winding). The light is a headlight (along the view
direction).

One GL context is created lazily per process and shared by all :class:`Renderer` objects (see
:func:`gl_context` about worker processes).
"""
from __future__ import annotations

import os

import numpy as np

from .io import atomic_output
from .mesh import vertex_normals

MODES = ("shaded", "normals", "depth", "colors")
#: The shader's mode index that draws "shaded" (red) and "depth" (green) in one pass: the CNN
#: input's two channels from one render and one read-back (the depth test picks the same fragment).
_SHADED_DEPTH = len(MODES)
VIEWS = {"front": 0.0, "three_quarter": -45.0, "side": -90.0}  # rotation about +y, degrees
MARGIN = 0.05  # fraction of the half image left free on each side of the framed box

_VERTEX_SHADER = """
#version 330
in vec3 in_pos;      // normalised device coordinates
in vec3 in_normal;   // camera frame
in vec3 in_color;
out vec3 v_normal;
out vec3 v_color;
void main() {
    gl_Position = vec4(in_pos, 1.0);
    v_normal = in_normal;
    v_color = in_color;
}
"""

_FRAGMENT_SHADER = """
#version 330
uniform int mode;    // index into MODES
in vec3 v_normal;
in vec3 v_color;
out vec4 f_color;
void main() {
    vec3 n = normalize(v_normal + vec3(1e-12));
    if (!gl_FrontFacing) n = -n;                   // two-sided
    float lambert = abs(n.z);                      // headlight along +z (towards the camera)
    vec3 rgb;
    if (mode == 0)      rgb = vec3(0.15 + 0.85 * lambert);
    else if (mode == 1) rgb = 0.5 * (n + 1.0);
    else if (mode == 2) rgb = vec3(1.0 - gl_FragCoord.z);   // near = bright
    else if (mode == 3) rgb = v_color * (0.3 + 0.7 * lambert);
    else                rgb = vec3(0.15 + 0.85 * lambert, 1.0 - gl_FragCoord.z, 0.0);
    f_color = vec4(rgb, 1.0);
}
"""

_CONTEXT = None
_CONTEXT_PID = None


def gl_context():
    """The process's moderngl standalone EGL context, created on first use.

    EGL (Mesa llvmpipe) cannot start again in a process forked after its parent created a context
    (it hangs), so that case raises RuntimeError: render in the parent, or start worker processes
    with the "spawn" method (e.g. ``DataLoader(..., multiprocessing_context="spawn")``).
    """
    global _CONTEXT, _CONTEXT_PID
    if _CONTEXT is not None and _CONTEXT_PID != os.getpid():
        raise RuntimeError(
            "offscreen rendering in a process forked after its parent created the GL context would hang; "
            "render in the parent or use the 'spawn' start method for worker processes"
        )
    if _CONTEXT is None:
        import moderngl

        _CONTEXT = moderngl.create_standalone_context(backend="egl")
        _CONTEXT_PID = os.getpid()
    return _CONTEXT


def view_rotation(view: str) -> np.ndarray:
    """(3,3) rotation about +y applied to the mesh for a named view. "front" is the identity;
    "three_quarter" (−45°) and "side" (−90°) turn the character's left (+x) towards the camera."""
    if view not in VIEWS:
        raise ValueError(f"unknown view {view!r}; choose from {sorted(VIEWS)}")
    a = np.deg2rad(VIEWS[view])
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _box_to_ndc(lo: np.ndarray, hi: np.ndarray):
    """Centre (3,) and per-axis scale (3,) mapping the box [lo, hi] (camera frame) into NDC:
    x, y share one scale (aspect kept) so the larger of width/height spans 2·(1−MARGIN); z is
    flipped (NDC −1 = nearest = largest camera z) and spans 2·(1−MARGIN)."""
    centre = 0.5 * (lo + hi)
    ext = np.maximum(hi - lo, 1e-12)
    sxy = 2.0 * (1.0 - MARGIN) / max(ext[0], ext[1])
    return centre, np.array([sxy, sxy, -2.0 * (1.0 - MARGIN) / ext[2]])


class Renderer:
    """Offscreen renderer of square images.

    size: image side in pixels. The framebuffer is float32 RGBA; images come back (H,W,C) float32
    in [0,1], row 0 at the top.
    """

    def __init__(self, size: int = 256):
        self.size = int(size)
        ctx = gl_context()
        self._ctx = ctx
        self._program = ctx.program(vertex_shader=_VERTEX_SHADER, fragment_shader=_FRAGMENT_SHADER)
        self._fbo = ctx.framebuffer(
            color_attachments=[ctx.texture((self.size, self.size), 4, dtype="f4")],
            depth_attachment=ctx.depth_renderbuffer((self.size, self.size)),
        )

    def render(self, verts, faces, mode: str = "shaded", vertex_colors=None, view: str = "front",
               fit=True) -> np.ndarray:
        """Render one mesh.

        verts (V,3) float, faces (F,3) int. mode: "shaded" (Lambert grey), "normals" ((n+1)/2, camera
        frame), "depth" (near = 1, far ≈ 0, background 0) or "colors" (vertex_colors (V,3) in [0,1],
        lit). view: "front", "three_quarter" or "side". fit: True frames the bounding box of the
        (rotated) mesh; a (2,3) array [min, max] frames that box instead (e.g. one camera for a whole
        sequence); False takes verts as normalised device coordinates already.
        Returns (H,W,3) float32, or (H,W,1) for depth; background 0.
        """
        return self.render_modes(verts, faces, (mode,), vertex_colors, view, fit)[0]

    def render_modes(self, verts, faces, modes, vertex_colors=None, view: str = "front",
                     fit=True, normals=None) -> list[np.ndarray]:
        """``[render(verts, faces, mode=m, ...) for m in modes]``, the mesh prepared and uploaded
        once (the CNN input renders two modes of every frame). ``normals``: the unit vertex
        normals (V,3) of ``verts`` if computed already."""
        for mode in modes:
            if mode not in MODES:
                raise ValueError(f"unknown render mode {mode!r}; choose from {MODES}")
        v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
        f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        rot = view_rotation(view)
        cam = v @ rot.T
        normals = (vertex_normals(v, f) if normals is None
                   else np.asarray(normals, np.float64).reshape(-1, 3)) @ rot.T
        if fit is not False:
            if fit is True:
                lo, hi = cam.min(axis=0), cam.max(axis=0)
            else:
                box = np.asarray(fit, dtype=np.float64).reshape(2, 3)
                corners = np.stack(np.meshgrid(*box.T, indexing="ij"), -1).reshape(-1, 3) @ rot.T
                lo, hi = corners.min(axis=0), corners.max(axis=0)
            centre, scale = _box_to_ndc(lo, hi)
            cam = (cam - centre) * scale
        else:
            cam = cam * np.array([1.0, 1.0, -1.0])
        if "colors" in modes:
            if vertex_colors is None:
                raise ValueError('mode "colors" needs vertex_colors (V,3)')
            colors = np.asarray(vertex_colors, dtype=np.float32).reshape(len(v), 3)
        else:
            colors = np.zeros((len(v), 3), dtype=np.float32)

        ctx = self._ctx
        data = np.hstack([cam, normals, colors]).astype("f4")
        vbo = ctx.buffer(data.tobytes())
        ibo = ctx.buffer(f.astype("i4").tobytes())
        vao = ctx.vertex_array(self._program, [(vbo, "3f 3f 3f", "in_pos", "in_normal", "in_color")],
                               index_buffer=ibo, index_element_size=4)
        images = []
        try:
            self._fbo.use()
            ctx.enable(ctx.DEPTH_TEST)
            ctx.disable(ctx.CULL_FACE)
            if len(modes) > 1 and set(modes) <= {"shaded", "depth"}:
                img = self._draw(vao, _SHADED_DEPTH)
                planes = {"shaded": np.repeat(img[..., :1], 3, axis=-1), "depth": img[..., 1:2]}
                return [np.ascontiguousarray(planes[m]) for m in modes]
            for mode in modes:
                img = self._draw(vao, MODES.index(mode))
                images.append(np.ascontiguousarray(img[..., :1] if mode == "depth" else img[..., :3]))
        finally:
            vao.release()
            vbo.release()
            ibo.release()
        return images


    def _draw(self, vao, mode_index: int) -> np.ndarray:
        """Clear, draw ``vao`` in shader mode ``mode_index``, read back: (H,W,4) float32 in [0,1],
        row 0 at the top."""
        ctx = self._ctx
        ctx.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._program["mode"].value = mode_index
        vao.render()
        raw = self._fbo.read(components=4, dtype="f4")
        return np.clip(np.frombuffer(raw, dtype=np.float32).reshape(self.size, self.size, 4)[::-1],
                       0.0, 1.0)


_RENDERERS: dict = {}


def _renderer(size: int) -> Renderer:
    """One Renderer per image size, reused."""
    if int(size) not in _RENDERERS:
        _RENDERERS[int(size)] = Renderer(size)
    return _RENDERERS[int(size)]


def render_frontal(verts, faces, size: int = 256, channels=("shaded", "depth"),
                   fit=True, normals=None) -> np.ndarray:
    """The CNN input image: a front view framing the mesh's bounding box (``fit=True``), or a fixed
    box ``fit`` = [min, max] (2,3) in the vertices' frame (the face frame's
    ``Canonicaliser.render_fit``, so the image follows the face whatever the crop).

    verts (V,3), faces (F,3). channels: any of "shaded" (1 channel, grey), "depth" (1) and "normals"
    (3), stacked in the given order. Returns (C,H,W) float32 in [0,1]; with ``fit=True`` invariant
    to the mesh's scale and translation. ``normals``: the unit vertex normals (V,3) of ``verts``
    if computed already.
    """
    images = _renderer(size).render_modes(verts, faces, tuple(channels), fit=fit, normals=normals)
    planes = [img[..., :1] if ch == "shaded" else img for ch, img in zip(channels, images)]
    return np.ascontiguousarray(np.concatenate(planes, axis=-1).transpose(2, 0, 1))


def heatmap_colors(values, vmax: float) -> np.ndarray:
    """Per-vertex colours for an error heatmap: values (V,) (e.g. errors in mm) on the fixed scale
    [0, vmax] through matplotlib's YlOrRd (values above vmax saturate). Returns (V,3) float32."""
    from matplotlib import colormaps

    t = np.clip(np.asarray(values, dtype=np.float64) / float(vmax), 0.0, 1.0)
    return colormaps["YlOrRd"](t)[:, :3].astype(np.float32)


def to_uint8(img) -> np.ndarray:
    """(H,W), (H,W,1), (H,W,3) or (H,W,4) float in [0,1] (or uint8) -> (H,W,3|4) uint8."""
    a = np.asarray(img)
    if a.dtype != np.uint8:
        a = (np.clip(a, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    if a.ndim == 2:
        a = a[..., None]
    return np.repeat(a, 3, axis=-1) if a.shape[-1] == 1 else a


def save_png(path, img) -> None:
    """Write an image (see :func:`to_uint8` for the accepted layouts) as PNG, atomically."""
    from PIL import Image

    with atomic_output(path) as tmp:
        Image.fromarray(to_uint8(img)).save(tmp, format="PNG")


def contact_sheet(images, labels=None, cols: int = 8, label_height: int = 14) -> np.ndarray:
    """Tile images of one size into a grid with a text label under each.

    images: sequence of (H,W,C) arrays (C = 1 or 3, float in [0,1] or uint8); labels: one string per
    image (or None); cols: tiles per row. Returns (rows·(H+label_height), cols·W, 3) float32 in [0,1].
    """
    from PIL import Image, ImageDraw

    tiles = [to_uint8(im)[..., :3] for im in images]
    if not tiles:
        raise ValueError("contact_sheet needs at least one image")
    h, w = tiles[0].shape[:2]
    cols = max(1, min(int(cols), len(tiles)))
    rows = -(-len(tiles) // cols)
    sheet = Image.new("RGB", (cols * w, rows * (h + label_height)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for i, tile in enumerate(tiles):
        x, y = (i % cols) * w, (i // cols) * (h + label_height)
        sheet.paste(Image.fromarray(tile), (x, y))
        if labels is not None:
            draw.text((x + 2, y + h + 1), str(labels[i]), fill=(0, 0, 0))
    return np.asarray(sheet, dtype=np.float32) / 255.0

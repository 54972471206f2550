"""Mesh files in and out: OBJ, PLY, OFF, GLB and GLTF.

Reading keeps the file's vertex order and count exactly (no merging of duplicate positions, no
removal of unreferenced vertices, no splitting at UV seams), because vertex i of one frame must be
vertex i of the next. PLY is read with trimesh (``process=False, maintain_order=True``). OBJ and OFF
are parsed here: trimesh splits an OBJ with several objects/groups/materials into parts that each
carry every vertex, needs an extra package for non-UTF-8 text, and mis-reads OFF polygons. Quads and
polygons are triangulated as fans. GLB/GLTF are read directly (pygltflib): every triangle
primitive of every mesh node of the default scene is concatenated in scene order (depth-first
over the scene's root nodes, children in file order, primitives in file order) with the node's world
transform applied — a multi-part head (face, eyes, teeth) comes in as one mesh whose parts follow
the file. Morph targets, skins and materials are ignored.

Every failure a user can cause (missing file, folder given, unknown extension, unreadable or
truncated file, empty mesh, NaN coordinates, point cloud, bad indices, frames that do not match)
raises :class:`RetargetError` with one line naming the file. Only regular files are read (a FIFO or
device would block or never end; a symlink loop is named as such), and a glTF's external buffers
must be regular files inside the glTF's own folder. Text is UTF-8 (with or without a byte-order
mark), UTF-16 or, failing those, Latin-1. Writes are atomic (temporary file in the destination
folder, then ``os.replace``), so an error never leaves a partial output behind; the temporary names
carry the writer's process id, and leftovers of a killed writer (SIGKILL) are removed by the next
write into the same folder. :func:`check_output` refuses an output that is one of the inputs.
"""
from __future__ import annotations

import base64
import codecs
import errno
import glob as globmod
import math
import os
import re
import shutil
import stat
import tempfile
import urllib.parse
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import RetargetError, RetargetWarning
from .mesh import Mesh, as_mesh, check_mesh, is_mesh_like, mesh_parts

READ_FORMATS = (".obj", ".ply", ".off", ".glb", ".gltf")
WRITE_FORMATS = (".obj", ".ply")
MAX_VERTICES = 10_000_000  # larger meshes are refused unless force=True
# Rough peak memory per vertex of processing a mesh (bytes): parsing (the OBJ reader peaks at
# ~0.9 KiB/vertex, tracemalloc on a 164k-vertex sphere), the mesh, normals and canonical
# features (~0.2 KiB), per-vertex decoding of 128-wide codes in chunks and the outputs (~1 KiB).
BYTES_PER_VERTEX = 2048
_MIN_BYTES_PER_VERTEX = 8  # no format stores a vertex in fewer bytes ("v 0 0 0\n")
#: glTF extensions that a file may require and this reader still reads right: they change
#: materials, textures or lights, not the geometry (KHR_mesh_quantization: integer positions,
#: which the accessor reader maps). Any other required extension (Draco, meshopt) is refused.
GLTF_EXTENSIONS_READ = ("KHR_mesh_quantization", "KHR_lights_punctual", "KHR_materials_*",
                        "KHR_texture_*", "EXT_texture_webp")
_AXES = {f"{s}{a}": (1.0 if s == "+" else -1.0) * np.eye(3)[i] for i, a in enumerate("xyz") for s in "+-"}


# ----------------------------------------------------------------------------------------- writing
@contextmanager
def atomic_output(path):
    """Write a file atomically: yields a temporary path in the destination folder, renamed onto
    ``path`` (os.replace) only if the block succeeds; on any error the temporary file is removed, so
    no partial output is left. Parent folders are created. The temporary name keeps the extension.

    Raises RetargetError naming ``path`` if the folder cannot be created or written, or ``path`` is a
    folder.
    """
    path = Path(path)
    if path.is_dir():
        raise RetargetError(f"{path}: is a folder, not an output file")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path.parent)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temporary_prefix(path), suffix=f".tmp{path.suffix}")
    except OSError as e:
        raise RetargetError(f"{path}: cannot write to folder {path.parent} ({e.strerror or e})") from None
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 would make outputs private
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        raise RetargetError(f"{path}: cannot write ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


_TEMPORARY = re.compile(r"^\..+\.pid(\d+)\.[A-Za-z0-9_]+\.tmp")


def temporary_prefix(path) -> str:
    """Name prefix of the temporary files and staging folders written for ``path``: hidden, with
    this process's id, so :func:`remove_stale_temporaries` can tell a killed writer's leftovers."""
    return f".{Path(path).name}.pid{os.getpid()}."


_CLEANED: set = set()  # folders already cleaned by this process


def remove_stale_temporaries(folder) -> None:
    """Remove the temporary files and staging folders (named by :func:`temporary_prefix`, then a
    random part and ``.tmp``) in ``folder`` whose writing process no longer runs: what a SIGKILL
    left behind. Those of running processes (another write in progress) are kept. Each folder is
    looked at once per process (a take of many frames does not list its folder per frame)."""
    key = os.path.abspath(folder)
    if key in _CLEANED:
        return
    _CLEANED.add(key)
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        m = _TEMPORARY.match(entry.name)
        if not m or _process_runs(int(m.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            try:
                os.remove(entry.path)
            except OSError:
                pass


def _process_runs(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # another user's process (or an absurd number): leave its files alone
    return True


def _resolve(path: Path) -> Path:
    """``path.resolve()``; RetargetError naming it for a symlink loop."""
    try:
        return path.resolve()
    except (RuntimeError, OSError):
        raise RetargetError(f"{path}: is a symlink loop") from None


def regular_file(path, what: str = "file", missing: str = "no such file") -> Path:
    """``path`` as a Path if it is a regular file (symlinks followed); else RetargetError naming it:
    ``missing`` (also a dangling symlink), a folder, a symlink loop, or a FIFO, device or socket
    (reading those blocks forever or never ends). ``what`` names the file wanted in the message."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise RetargetError(f"{path}: {missing}") from None
    except OSError as e:
        problem = "is a symlink loop" if e.errno == errno.ELOOP else f"cannot read ({e.strerror or e})"
        raise RetargetError(f"{path}: {problem}") from None
    if stat.S_ISDIR(mode):
        raise RetargetError(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(mode):
        kind = ("a named pipe (FIFO)" if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode)
                or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise RetargetError(f"{path}: is {kind}, not a {what}; only regular files are read")
    return path


def read_text(path) -> str:
    """A text file as str: UTF-8 (a byte-order mark dropped), UTF-16 (with a byte-order mark, or
    ASCII text with every other byte zero), else Latin-1 (old exporters); RetargetError for binary
    data (NUL characters)."""
    path = Path(path)
    data = path.read_bytes()
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        codec = "utf-16"
    elif len(data) >= 2 and len(data) % 2 == 0 and not data[1::2].strip(b"\0") and b"\0" not in data[0::2]:
        codec = "utf-16-le"
    elif len(data) >= 2 and len(data) % 2 == 0 and not data[0::2].strip(b"\0") and b"\0" not in data[1::2]:
        codec = "utf-16-be"
    else:
        codec = "utf-8-sig"
    try:
        text = data.decode(codec)
    except UnicodeDecodeError:
        text = data.decode("latin-1") if codec == "utf-8-sig" else "\0"
    if "\0" in text:
        raise RetargetError(f"{path}: holds binary data, not a text {path.suffix[1:].upper()} file")
    return text


def check_output(out_path, input_paths, formats: tuple[str, ...] | None = None) -> None:
    """Raise RetargetError if ``out_path`` is ``-`` (standard output is not written), a symlink loop,
    not one of ``formats`` (extensions, if given) or (resolves to, or is a hard link of) any input
    file."""
    out = Path(out_path)
    if str(out_path) == "-":
        raise RetargetError("-: writing to standard output is not supported; give an output file "
                            "(./- for a file named -)")
    if formats is not None and out.suffix.lower() not in formats:
        raise RetargetError(f"{out}: this output is written as {' or '.join(formats)}, not "
                            f"{out.suffix or 'a file without extension'}")
    out_resolved = _resolve(out)
    for inp in input_paths:
        inp = Path(inp)
        same = out_resolved == _resolve(inp)
        if not same and out.exists() and inp.exists():
            same = os.path.samefile(out, inp)
        if same:
            raise RetargetError(f"{out}: refusing to overwrite the input file {inp}; choose another output")


def save_mesh(path, mesh_or_vertices, faces=None) -> None:
    """Write a mesh as OBJ (text, vertices with 9 decimals) or PLY (binary, float32), atomically.

    mesh_or_vertices: a mesh (anything :func:`retarget.mesh.as_mesh` takes: a Mesh, a
    trimesh.Trimesh, a (vertices, faces) pair), or (V,3) vertices with ``faces`` (F,3). Vertex order
    is kept. RetargetError for an unknown extension or an unwritable destination.
    """
    import trimesh

    path = Path(path)
    if path.suffix.lower() not in WRITE_FORMATS:
        raise RetargetError(f"{path}: cannot write {path.suffix or 'files without extension'}; "
                            f"use {', '.join(WRITE_FORMATS)}")
    if faces is None and is_mesh_like(mesh_or_vertices):
        mesh = as_mesh(mesh_or_vertices, role=str(path))
        verts, faces = mesh.vertices, mesh.faces
    else:
        verts = np.asarray(mesh_or_vertices, dtype=np.float64)
        faces = np.zeros((0, 3), np.int64) if faces is None else np.asarray(faces, dtype=np.int64)
    tm = trimesh.Trimesh(verts, faces, process=False, validate=False)
    with atomic_output(path) as tmp:
        if path.suffix.lower() == ".obj":
            tm.export(tmp, file_type="obj", include_normals=False, include_texture=False, digits=9)
        else:
            tm.export(tmp, file_type="ply", encoding="binary")


# ----------------------------------------------------------------------------------------- reading
def axis_rotation(up: str | None = None, forward: str | None = None) -> np.ndarray:
    """(3,3) rotation taking a mesh whose up/forward axes are ``up``/``forward`` (e.g. "+z", "-y")
    into the project frame (+y up, +z forward, right-handed). Apply as ``v @ R.T``; ``R.T`` maps
    back. A missing axis defaults to the project's (+y up, +z forward)."""
    names = {"up": up or "+y", "forward": forward or "+z"}
    for key, val in names.items():
        if val.lower() not in _AXES:
            raise RetargetError(f"--{key} {val!r}: expected one of {', '.join(_AXES)}")
    u, f = _AXES[names["up"].lower()], _AXES[names["forward"].lower()]
    if abs(u @ f) > 0:
        raise RetargetError(f"--up {names['up']} and --forward {names['forward']} must be different axes")
    return np.stack([np.cross(u, f), u, f])


def peek_vertex_count(path) -> int | None:
    """The vertex count from a file's header (PLY, OFF, GLB/GLTF) or by counting ``v`` lines (OBJ),
    without parsing the geometry; None if it cannot be told."""
    path = Path(path)
    ext = path.suffix.lower()
    try:
        if ext in (".ply", ".off"):
            with open(path, "rb") as fh:
                head = fh.read(4096).decode("latin-1")
            m = (re.search(r"element\s+vertex\s+(\d+)", head) if ext == ".ply"
                 else re.search(r"^\s*[A-Z]*OFF\s+(\d+)|^\s*(\d+)\s+\d+", re.sub(r"#.*", "", head), re.M))
            return int(next(g for g in m.groups() if g)) if m else None
        if ext == ".obj":
            count, prev = 0, b"\n"
            with open(path, "rb") as fh:
                while chunk := fh.read(1 << 24):
                    count += (prev + chunk).count(b"\nv ") + (prev + chunk).count(b"\nv\t")
                    prev = chunk[-1:]
            return count
        if ext in (".glb", ".gltf"):
            gltf = _load_gltf(path)
            return sum(gltf.accessors[p.attributes.POSITION].count
                       for m in gltf.meshes for p in m.primitives if p.attributes.POSITION is not None)
    except Exception:  # a file the header cannot be read from: the reader will say why
        return None
    return None


def check_fps(fps, where: str = "--fps") -> float:
    """``fps`` as a float if it is a finite number above 0; else RetargetError naming ``where``
    (animation times are t / fps, and the filters divide by it)."""
    try:
        value = float(fps)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise RetargetError(f"{where} {str(fps)[:40]}: the frame rate must be a finite number above 0")
    return value


def estimate_memory(n_vertices: int) -> int:
    """Rough peak memory (bytes) of processing a mesh of ``n_vertices`` (see BYTES_PER_VERTEX)."""
    return int(n_vertices) * BYTES_PER_VERTEX


def check_vertex_budget(n_vertices: int, path, limit: int = MAX_VERTICES, force: bool = False) -> None:
    """RetargetError (stating the memory it would need) for a mesh above ``limit`` vertices,
    unless ``force``."""
    if n_vertices > limit and not force:
        raise RetargetError(
            f"{path}: {n_vertices:,} vertices is above the limit of {limit:,}; it would need about "
            f"{estimate_memory(n_vertices) / 2**30:.1f} GiB of memory (use --force to try anyway)"
        )


def load_mesh(path, up: str | None = None, forward: str | None = None, force: bool = False,
              max_vertices: int = MAX_VERTICES, check_parts: bool = True) -> Mesh:
    """Read and validate a triangle mesh.

    path: .obj, .ply, .off, .glb or .gltf. up/forward: the file's axes (e.g. up="+z", forward="-y")
    if they are not the project's +y up / +z forward; the mesh is rotated into the project frame.
    Meshes above ``max_vertices`` are refused before parsing unless ``force``. ``check_parts``:
    warn when the file looks like two heads (:func:`warn_if_several_heads`).
    Returns Mesh(vertices (V,3) float64 in the file's units, faces (F,3) int64, name=str(path)).
    """
    path = regular_file(path, "mesh file")
    ext = path.suffix.lower()
    if ext not in READ_FORMATS:
        raise RetargetError(f"{path}: unknown mesh format {ext or '(no extension)'}; "
                            f"expected {', '.join(READ_FORMATS)}")
    if path.stat().st_size >= _MIN_BYTES_PER_VERTEX * max_vertices:
        n = peek_vertex_count(path)
        if n is not None:
            check_vertex_budget(n, path, max_vertices, force)
    try:
        verts, faces = _READERS[ext](path)
    except RetargetError:
        raise
    except Exception as e:  # any parser failure on a user file is a user error
        reason = f"{type(e).__name__}: {e}".splitlines()[0]
        raise RetargetError(f"{path}: cannot read as {ext[1:].upper()} ({reason})") from None
    mesh = check_mesh(Mesh(verts, faces, name=str(path)), path)
    if check_parts:
        warn_if_several_heads(mesh, path)
    if up is not None or forward is not None:
        mesh = Mesh(mesh.vertices @ axis_rotation(up, forward).T, mesh.faces, mesh.name)
    return mesh


class SeveralHeadsWarning(RetargetWarning):
    """A mesh file holds two or more similar parts side by side (two heads?)."""


def warn_if_several_heads(mesh: Mesh, path) -> None:
    """SeveralHeadsWarning if the two largest parts of the mesh (``retarget.mesh.mesh_parts``,
    welded along seams) each hold at least a quarter of its vertices and their bounding boxes are
    apart: most likely two heads in one file, which the network would treat as one. (Eyes, teeth
    and other small parts do not count.)"""
    labels = mesh_parts(mesh.vertices, mesh.faces)
    count = int(labels.max()) + 1
    if count < 2:
        return
    sizes = np.bincount(labels[labels >= 0], minlength=count)
    a, b = np.argsort(sizes)[::-1][:2]
    if sizes[b] < 0.25 * (labels >= 0).sum():
        return
    va, vb = mesh.vertices[labels == a], mesh.vertices[labels == b]
    if (va.min(0) > vb.max(0)).any() or (vb.min(0) > va.max(0)).any():
        warnings.warn(f"{path}: holds {count} disconnected parts, two of them of similar size side by "
                      f"side ({sizes[a]:,} and {sizes[b]:,} vertices): two heads? The file is "
                      "treated as one head", SeveralHeadsWarning, stacklevel=3)


def _read_ply(path: Path):
    """PLY (ASCII or binary, trimesh) -> vertices (V,3), faces (F,3); point clouds give F=0."""
    import trimesh

    loaded = trimesh.load(str(path), process=False, maintain_order=True)
    verts = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)  # PointCloud: none
    return verts, faces.reshape(-1, 3)


def _fan(polygons) -> np.ndarray:
    """Polygons (lists of vertex indices) -> (F,3) int64 triangles (v0, vk, vk+1)."""
    tris = [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)]
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _read_obj(path: Path):
    """OBJ -> vertices (V,3) in the order of the ``v`` lines, faces (F,3) in the order of the ``f``
    lines, whatever the objects, groups and materials (trimesh would split those into parts);
    ``a/b/c`` and negative (relative) indices accepted, polygons fanned, everything else ignored."""
    verts, polygons = [], []
    for line, raw in enumerate(read_text(path).splitlines(), start=1):
        tok = raw.split()
        if not tok:
            continue
        if tok[0] == "v":
            if len(tok) < 4:
                raise ValueError(f"a vertex line has fewer than 3 coordinates: {raw.strip()[:80]!r}")
            verts.append(tok[1:4])
        elif tok[0] == "f":
            n = len(verts)
            idx = [int(t.split("/")[0]) for t in tok[1:]]
            if 0 in idx:
                raise RetargetError(f"{path}: line {line}: face index 0 (OBJ vertex indices start at 1)")
            polygons.append([i - 1 if i > 0 else n + i for i in idx])
    return np.array(verts, dtype=np.float64).reshape(-1, 3), _fan(polygons)


def _read_off(path: Path):
    """OFF (also COFF/NOFF/..., whose extra per-vertex values are ignored) -> vertices (V,3),
    faces (F,3); polygons fanned, comments (#) allowed. (trimesh mis-reads OFF polygons.)"""
    lines = [ln.split() for ln in (raw.split("#", 1)[0] for raw in read_text(path).splitlines())
             if ln.strip()]
    if not lines or not lines[0][0].endswith("OFF"):
        raise ValueError("the file does not start with OFF")
    counts = lines[0][1:] or lines[1]
    start = 1 if lines[0][1:] else 2
    nv, nf = int(counts[0]), int(counts[1])
    verts = np.array([[float(x) for x in ln[:3]] for ln in lines[start:start + nv]], dtype=np.float64)
    if len(verts) != nv or nf > len(lines) - start - nv:
        raise ValueError(f"the header announces {nv} vertices and {nf} faces but the file is shorter")
    polygons = [[int(i) for i in ln[1:1 + int(ln[0])]] for ln in lines[start + nv:start + nv + nf]]
    return verts.reshape(-1, 3), _fan(polygons)


def _load_gltf(path: Path):
    import pygltflib

    gltf = pygltflib.GLTF2().load(str(path))
    if gltf is None:
        raise RetargetError(f"{path}: not a glTF file")
    return gltf


_GL_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_GL_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _check_gltf_extensions(gltf, path: Path) -> None:
    """RetargetError naming the required extensions that this reader does not read (compressed
    geometry would otherwise be read as garbage)."""
    from fnmatch import fnmatchcase

    unknown = [e for e in (gltf.extensionsRequired or [])
               if not any(fnmatchcase(str(e), pat) for pat in GLTF_EXTENSIONS_READ)]
    if unknown:
        raise RetargetError(f"{path}: requires the glTF extension(s) {', '.join(map(str, unknown[:5]))}, "
                            "which this reader does not support (compressed geometry?); re-export "
                            "without compression")


def _gltf_buffers(gltf, path: Path) -> list[bytes]:
    """The bytes of every glTF buffer: the GLB chunk, a data URI or a file given by a relative URI,
    which must be a regular file inside the glTF's folder (an absolute path, another scheme, a
    device or a path escaping the folder is refused); at most ``byteLength`` bytes are read."""
    out, folder = [], _resolve(path.parent)
    for i, buf in enumerate(gltf.buffers):
        if buf.uri is None:
            out.append(gltf.binary_blob() or b"")
            continue
        if buf.uri.startswith("data:"):
            out.append(base64.b64decode(buf.uri.split(",", 1)[1]))
            continue
        uri = urllib.parse.unquote(buf.uri)
        where = f"{path}: buffer {i} (uri {buf.uri[:100]!r})"
        if urllib.parse.urlsplit(buf.uri).scheme or os.path.isabs(uri):
            raise RetargetError(f"{where} is not a relative path; a glTF may only use files in its own folder")
        file = path.parent / uri
        if not _resolve(file).is_relative_to(folder):
            raise RetargetError(f"{where} points outside the glTF's folder {path.parent}")
        try:
            regular_file(file, "buffer file")
        except RetargetError as e:
            raise RetargetError(f"{where}: {str(e).split(': ', 1)[1]}") from None
        size = buf.byteLength if isinstance(buf.byteLength, int) and buf.byteLength >= 0 else None
        with open(file, "rb") as fh:
            out.append(fh.read(size) if size is not None else fh.read())
    return out


def _gltf_accessor(gltf, buffers, index: int, path: Path) -> np.ndarray:
    """Accessor ``index`` as an (count, width) array (normalised integers mapped to [−1, 1])."""
    acc = gltf.accessors[index]
    if acc.sparse is not None or acc.bufferView is None:
        raise RetargetError(f"{path}: accessor {index} is sparse or has no data (Draco-compressed?); "
                            "re-export without compression")
    dtype, width = np.dtype(_GL_DTYPES[acc.componentType]), _GL_WIDTH[acc.type]
    view = gltf.bufferViews[acc.bufferView]
    data = buffers[view.buffer]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    stride = view.byteStride or dtype.itemsize * width
    end = start + stride * (acc.count - 1) + dtype.itemsize * width if acc.count else start
    if end > len(data):
        raise RetargetError(f"{path}: truncated (accessor {index} needs {end} bytes, buffer has {len(data)})")
    arr = np.ndarray((acc.count, width), dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
    if acc.normalized and dtype.kind in "iu":
        return np.maximum(arr / np.iinfo(dtype).max, -1.0)
    return np.array(arr)


def _node_matrix(node) -> np.ndarray:
    """A glTF node's local 4x4 transform (matrix, or T·R·S)."""
    from scipy.spatial.transform import Rotation

    if node.matrix is not None:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    m = np.eye(4)
    if node.scale is not None:
        m = np.diag([*node.scale, 1.0]) @ m
    if node.rotation is not None:
        r = np.eye(4)
        r[:3, :3] = Rotation.from_quat(node.rotation).as_matrix()  # glTF quaternions are x, y, z, w
        m = r @ m
    if node.translation is not None:
        m[:3, 3] += node.translation
    return m


def _read_gltf(path: Path):
    """GLB/GLTF -> vertices (V,3), faces (F,3): every triangle primitive of the default scene,
    concatenated depth-first in scene order with world transforms applied."""
    gltf = _load_gltf(path)
    _check_gltf_extensions(gltf, path)
    buffers = _gltf_buffers(gltf, path)
    if gltf.scenes:
        roots = gltf.scenes[gltf.scene or 0].nodes or []
    else:  # no scene: every node that is nobody's child
        children = {c for n in gltf.nodes for c in (n.children or [])}
        roots = [i for i in range(len(gltf.nodes)) if i not in children]
    verts, faces, offset = [], [], 0
    stack, seen = [(n, np.eye(4)) for n in reversed(roots)], set()
    while stack:
        index, parent = stack.pop()
        if index in seen:
            raise RetargetError(f"{path}: node {index} is reached twice (the node hierarchy has a cycle)")
        seen.add(index)
        node = gltf.nodes[index]
        world = parent @ _node_matrix(node)
        stack.extend((c, world) for c in reversed(node.children or []))
        if node.mesh is None:
            continue
        for prim in gltf.meshes[node.mesh].primitives:
            if prim.mode not in (None, 4):
                raise RetargetError(f"{path}: primitive mode {prim.mode} is not triangles; triangulate on export")
            if prim.attributes.POSITION is None:
                continue
            p = _gltf_accessor(gltf, buffers, prim.attributes.POSITION, path).astype(np.float64)
            idx = (np.arange(len(p)) if prim.indices is None
                   else _gltf_accessor(gltf, buffers, prim.indices, path).ravel().astype(np.int64))
            if len(idx) % 3:
                raise RetargetError(f"{path}: a triangle primitive has {len(idx)} indices (not a multiple of 3)")
            verts.append(p @ world[:3, :3].T + world[:3, 3])
            faces.append(idx.reshape(-1, 3) + offset)
            offset += len(p)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(verts), np.concatenate(faces)


_READERS = {".obj": _read_obj, ".ply": _read_ply, ".off": _read_off, ".glb": _read_gltf, ".gltf": _read_gltf}


def _natural_key(path: Path):
    """Sort key putting frame_2 before frame_10."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", str(path))]


def sequence_files(spec) -> list[Path]:
    """The mesh files of a sequence given as a folder (its mesh files), a glob pattern or one file
    (a name that exists, ``a[1].obj`` included, is a file, never a pattern), sorted naturally.
    RetargetError if nothing matches."""
    spec = str(spec)
    if os.path.isdir(spec):
        files = [p for p in Path(spec).iterdir() if p.is_file() and p.suffix.lower() in READ_FORMATS]
    elif globmod.has_magic(spec) and not os.path.lexists(spec):  # an existing name is taken literally
        files = [Path(p) for p in globmod.glob(spec) if os.path.isfile(p)]
    else:
        files = [Path(spec)]
    if not files:
        raise RetargetError(f"{spec}: no mesh files ({', '.join(READ_FORMATS)}) found")
    return sorted(files, key=_natural_key)


def load_sequence(spec, up: str | None = None, forward: str | None = None,
                  force: bool = False) -> list[Mesh]:
    """Read the frames of a sequence (folder, glob or single file; see :func:`sequence_files`).
    ``force``: read frames above the vertex limit anyway (see :func:`load_mesh`).

    All frames must share the first frame's vertex count and face array (RetargetError naming the
    first offending file). Shows a progress bar for long sequences on a terminal. The two-heads
    check runs on the first frame only (the frames share its parts): one warning, not one a frame.
    """
    from tqdm import tqdm

    files = sequence_files(spec)
    frames = []
    for f in tqdm(files, desc="reading frames", unit="frame", disable=True if len(files) < 20 else None):
        mesh = load_mesh(f, up=up, forward=forward, force=force, check_parts=not frames)
        if frames:
            first = frames[0]
            if mesh.n_vertices != first.n_vertices:
                raise RetargetError(f"{f}: has {mesh.n_vertices} vertices but {first.name} has "
                                    f"{first.n_vertices}; all frames of a sequence must match")
            if not np.array_equal(mesh.faces, first.faces):
                raise RetargetError(f"{f}: its faces differ from those of {first.name}; "
                                    "all frames must share one topology")
            mesh = Mesh(mesh.vertices, first.faces, mesh.name)  # share one face array
        frames.append(mesh)
    return frames

"""Regenerate the bad-input corpus in this folder: ``python tests/bad_inputs/make_corpus.py``.

Every file here is a small input that the readers must refuse with a RetargetError naming it. The
expected message fragments are in tests/test_io.py (meshes) and tests/test_weights_io.py (weights).
Cases that need the file system at run time (missing file, folder given as a mesh, read-only output,
output == input, FIFOs, devices, symlink loops, glob characters in names, leftovers of a killed
writer, a huge take) are built by the tests themselves (tests/test_bad_inputs_cli.py).
"""
from pathlib import Path

TRI = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"
PLY_HEAD = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
LLF_HEAD = "Timecode,BlendShapeCount,EyeBlinkLeft,JawOpen,HeadYaw\n"


def _glb_bytes() -> bytes:
    """A valid one-triangle GLB, written by the project's own exporter."""
    import tempfile

    import numpy as np

    from retarget.glb import write_rig_glb

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "tri.glb"
        tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
        write_rig_glb(path, tri, [[0, 1, 2]], np.zeros((1, 3, 3)), ["jawOpen"])
        return path.read_bytes()


def _gltf_variant(glb: bytes, **changes) -> bytes:
    """The one-triangle GLB as .gltf JSON (buffer as a data URI) with top-level fields replaced
    (``buffers``, ``extensionsRequired``, ``nodes``...)."""
    import json
    import tempfile

    import pygltflib

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "tri.glb").write_bytes(glb)
        gltf = pygltflib.GLTF2().load(str(Path(d) / "tri.glb"))
        gltf.convert_buffers(pygltflib.BufferFormat.DATAURI)
        data = json.loads(gltf.to_json())
    data.update(changes)
    return json.dumps(data).encode()


def _collinear_obj() -> bytes:
    """60 vertices on one line, written to 6 decimals (the rounding makes the faces' areas tiny but
    not zero), as a strip of 58 triangles whose bounding box looks like a head's."""
    lines = [f"v {0.1 + 1.1 * t / 7:.6f} {0.2 + 2.3 * t / 7:.6f} {0.3 + 3.7 * t / 7:.6f}"
             for t in (0.37 * i for i in range(60))]
    lines += [f"f {i} {i + 1} {i + 2}" for i in range(1, 59)]
    return ("\n".join(lines) + "\n").encode()


def corpus() -> dict:
    """file name -> bytes."""
    glb = _glb_bytes()
    buffer = {"byteLength": 36}
    junk = bytes((i * 97 + 13) % 256 for i in range(256))  # deterministic, contains NUL bytes
    return {
        # meshes
        "empty.obj": b"",
        "comments_only.obj": b"# nothing here\n# at all\n",
        "garbage.obj": junk,
        "garbage.ply": junk,
        "garbage.off": b"this is not an OFF file\nat all\n",
        "garbage.glb": junk,
        "truncated.glb": glb[: len(glb) - 40],
        "truncated.ply": PLY_HEAD.replace(b"ascii", b"binary_little_endian") + b"\x00\x01\x02",
        "nan.obj": TRI.replace(b"v 0 1 0", b"v 0 nan 0") + b"f 1 2 3\n",
        "inf.ply": PLY_HEAD + b"0 0 0\n1 0 0\n0 inf 0\n3 0 1 2\n",
        "degenerate.obj": b"v 0 0 0\nv 1 1 1\nv 2 2 2\nv 3 3 3\nf 1 2 3\nf 2 3 4\nf 1 1 2\n",
        "point_cloud.obj": TRI,
        "point_cloud.ply": PLY_HEAD.replace(b"element face 1\nproperty list uchar int vertex_indices\n", b"")
        + b"0 0 0\n1 0 0\n0 1 0\n",
        "index_out_of_range.obj": TRI + b"f 1 2 7\n",
        "index_out_of_range.off": b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n",
        "unknown_format.stl": b"solid x\nendsolid x\n",
        "face_index_zero.obj": TRI + b"f 0 1 2\n",
        "collinear.obj": _collinear_obj(),
        "huge_coordinate.obj": TRI.replace(b"v 1 0 0", b"v 1e300 0 0") + b"f 1 2 3\n",
        "buffer_absolute.gltf": _gltf_variant(glb, buffers=[{**buffer, "uri": "/etc/passwd"}]),
        "buffer_device.gltf": _gltf_variant(glb, buffers=[{**buffer, "uri": "/dev/zero"}]),
        "buffer_file_scheme.gltf": _gltf_variant(glb, buffers=[{**buffer, "uri": "file:///dev/zero"}]),
        "buffer_escapes.gltf": _gltf_variant(glb, buffers=[{**buffer, "uri": "../../../../etc/passwd"}]),
        "buffer_escapes_encoded.gltf": _gltf_variant(glb, buffers=[{**buffer, "uri": "%2E%2E/%2E%2E/x.bin"}]),
        "draco.gltf": _gltf_variant(glb, extensionsUsed=["KHR_draco_mesh_compression"],
                                    extensionsRequired=["KHR_draco_mesh_compression"]),
        "meshopt.gltf": _gltf_variant(glb, extensionsUsed=["EXT_meshopt_compression"],
                                      extensionsRequired=["EXT_meshopt_compression"]),
        "node_cycle.gltf": _gltf_variant(glb, nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}]),
        "seq_counts/frame_1.obj": TRI + b"f 1 2 3\n",
        "seq_counts/frame_2.obj": TRI + b"v 1 1 0\nf 1 2 3\nf 2 4 3\n",
        "seq_faces/frame_1.obj": TRI + b"f 1 2 3\n",
        "seq_faces/frame_2.obj": TRI + b"f 1 3 2\n",
        # weights
        "empty.csv": b"",
        "header_only.csv": b"jawOpen,eyeBlink_L\n",
        "no_header.csv": b"0.1,0.2\n0.3,0.4\n",
        "missing_cell.csv": b"jawOpen,eyeBlink_L\n0.1,0.2\n0.3,\n",
        "short_row.csv": b"jawOpen,eyeBlink_L\n0.1,0.2\n0.3\n",
        "long_row.csv": b"jawOpen,eyeBlink_L\n0.1,0.2,0.5\n",
        "text_in_number.csv": b"frame,jawOpen,eyeBlink_L\n0,0.1,0.2\n1,abc,0.4\n",
        "nan_weight.csv": b"jawOpen\nnan\n",
        "unknown_names.csv": b"jawOpen,smileBig,frownish\n0.1,0.2,0.3\n",
        "duplicate_names.csv": b"browInnerUp,browInnerUp_L\n0.1,0.2\n",
        "llf_text.csv": (LLF_HEAD + "10:00:00:01.000,52,0.1,0.2,0.0\n10:00:00:02.000,52,x,0.2,0.0\n").encode(),
        "unknown_format.txt": b"jawOpen\n0.5\n",
        "empty.json": b"",
        "bad_syntax.json": b'{"jawOpen": 0.5,,}',
        "wrong_shape.json": b"[0.1, 0.2, 0.3]",
        "wrong_shape_number.json": b"42",
        "names_mismatch.json": b'{"names": ["jawOpen", "eyeBlink_L"], "frames": [[0.1, 0.2], [0.3]]}',
        "unknown_names.json": b'{"jawOpen": 0.5, "tongueTwist": 0.1}',
        "text_in_number.json": b'[{"jawOpen": 0.5}, {"jawOpen": "half"}]',
        "null_value.json": b'{"jawOpen": null}',
        "only_commas.csv": b"jawOpen,eyeBlink_L\n0.1,0.2\n,\n0.3,0.4\n",
        "nul_bytes.csv": b"jawOpen\n0.5\x00\n",
        "wide.csv": (",".join(["jawOpen"] + [f"extra{i}" for i in range(10_000)]) + "\n"
                     + ",".join(["0.5"] * 10_001) + "\n").encode(),
        "huge_integer.json": b'{"jawOpen": 1' + b"0" * 5000 + b"}",
        "big_integer.json": b'{"jawOpen": 1' + b"0" * 400 + b"}",
        "huge_number.json": b'{"jawOpen": 1e300}',
        "deep.json": b"[" * 5000 + b"]" * 5000,
        "fps_zero.json": b'{"fps": 0, "frames": [{"jawOpen": 0.5}]}',
        "fps_negative.json": b'{"jawOpen": 0.5, "fps": -30}',
    }


def main() -> None:
    here = Path(__file__).parent
    for name, data in corpus().items():
        (here / name).parent.mkdir(parents=True, exist_ok=True)
        (here / name).write_bytes(data)


if __name__ == "__main__":
    main()

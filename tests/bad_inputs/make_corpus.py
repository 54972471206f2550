"""Regenerate the bad-input corpus in this folder: ``python tests/bad_inputs/make_corpus.py``.

Every file here is a small input that the readers must refuse with a RetargetError naming it. The
expected message fragments are in tests/test_io.py (meshes) and tests/test_weights_io.py (weights).
Cases that need the file system at run time (missing file, folder given as a mesh, read-only output,
output == input) are built by the tests themselves.
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


def corpus() -> dict:
    """file name -> bytes."""
    glb = _glb_bytes()
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
    }


def main() -> None:
    here = Path(__file__).parent
    for name, data in corpus().items():
        (here / name).parent.mkdir(parents=True, exist_ok=True)
        (here / name).write_bytes(data)


if __name__ == "__main__":
    main()

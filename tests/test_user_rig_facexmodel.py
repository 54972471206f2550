"""Fine-tuning on ICT-FaceKit's FaceXModel folder as it is published: a fixture laid out like it (the
neutral ``generic_neutral_mesh.obj``, the 53 ICT shapes plus PupilDilate_L/R and cheekRaiser_L/R,
identity shapes, an .mtl, OBJs with ``mtllib``/``usemtl``/``g`` lines, ``v/vt`` face corners and
quads, a non-skin part after the skin's vertex range)."""
from pathlib import Path

import numpy as np
import pytest
import trimesh

from data_synth.facs import FACS_NAMES, N_FACS
from data_synth.identity import sample_identity
from data_synth.rig import build_rig
from data_synth.tessellate import tessellate
from retarget.cli import main
from retarget.user_rig import UnknownShapeWarning, load_user_rig

ROOT = Path(__file__).resolve().parents[1]
EXTRAS = ("PupilDilate_L", "PupilDilate_R", "cheekRaiser_L", "cheekRaiser_R")


def quads_from_triangles(faces: np.ndarray) -> list[list[int]]:
    """Pair triangles sharing an edge into quads whose fan triangulation (v0, vk, vk+1) gives the
    two triangles back; unpaired triangles stay triangles."""
    edge_owner = {}
    for t, f in enumerate(faces):
        for k in range(3):
            edge_owner[(f[k], f[(k + 1) % 3])] = t
    used, polygons = np.zeros(len(faces), bool), []
    for t, (a, b, c) in enumerate(faces):
        if used[t]:
            continue
        used[t] = True
        u = edge_owner.get((c, b))                     # the neighbour across edge b-c: (c, b, d)
        if u is not None and not used[u]:
            used[u] = True
            d = next(int(x) for x in faces[u] if x not in (b, c))
            polygons.append([b, d, c, a])              # fans to (b, d, c) and (b, c, a)
        else:
            polygons.append([a, b, c])
    return polygons


def write_ict_obj(path: Path, skin: np.ndarray, eye: np.ndarray, skin_polys, eye_faces) -> None:
    lines = ["mtllib ICTFaceModelMaterial.mtl"]
    verts = np.vstack([skin, eye])
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"vt {0.5 + x / 40:.6f} {0.5 + y / 40:.6f}" for x, y, _ in verts]
    for group, polys, base in (("face", skin_polys, 0), ("eyeball_L", eye_faces, len(skin))):
        lines += [f"g {group}", "usemtl ICTFaceModelMaterial"]
        lines += ["f " + " ".join(f"{base + i + 1}/{base + i + 1}" for i in p) for p in polys]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def facexmodel(tmp_path_factory):
    """(folder, the procedural rig of its skin, number of skin vertices)."""
    rig = build_rig(sample_identity(2, split="test"), tessellate(400, kind="regular", seed=0))
    sphere = trimesh.creation.icosphere(subdivisions=1)
    eye = sphere.vertices * 1.2 + np.array([3.2, 3.0, 8.0])
    polys = quads_from_triangles(rig.faces)
    assert sum(len(p) == 4 for p in polys) > len(polys) // 2      # mostly quads, as ICT's mesh
    folder = tmp_path_factory.mktemp("ICT-FaceKit") / "FaceXModel"
    folder.mkdir()
    (folder / "ICTFaceModelMaterial.mtl").write_text("newmtl ICTFaceModelMaterial\nKd 0.8 0.8 0.8\n")
    write_ict_obj(folder / "generic_neutral_mesh.obj", rig.neutral, eye, polys, sphere.faces)
    for name, delta in zip(FACS_NAMES, rig.deltas):
        write_ict_obj(folder / f"{name}.obj", rig.neutral + delta, eye, polys, sphere.faces)
    rng = np.random.default_rng(0)
    for name in EXTRAS:   # the pupils move the eyeball only; the cheek raisers the skin
        pupil = name.startswith("Pupil")
        write_ict_obj(folder / f"{name}.obj", rig.neutral + (0 if pupil else 0.3), eye * (1.05 if pupil else 1),
                      polys, sphere.faces)
    for i in range(3):
        write_ict_obj(folder / f"identity{i:03d}.obj", rig.neutral + rng.normal(0, 0.2, rig.neutral.shape),
                      eye + 0.1, polys, sphere.faces)
    return folder, rig, len(rig.neutral)


def test_published_folder_loads_with_the_extras_left_out_in_one_warning(facexmodel):
    folder, proc, n_skin = facexmodel
    with pytest.warns(UnknownShapeWarning) as caught:
        rig = load_user_rig(folder, keep_vertices=f"0:{n_skin}")
    assert [str(w.message) for w in caught] == [
        f"{folder}: left out 4 shapes that have no ICT or ARKit name: "
        "PupilDilate_L, PupilDilate_R, cheekRaiser_L, cheekRaiser_R"]
    assert rig.present.all() and rig.n_vertices == n_skin
    # quads fanned back into the skin's own triangles, vertex order kept, the eyeball cut off
    assert {tuple(np.roll(f, -np.argmin(f))) for f in rig.faces} == \
        {tuple(np.roll(f, -np.argmin(f))) for f in proc.faces}
    np.testing.assert_allclose(rig.neutral, proc.neutral, atol=1e-5)
    np.testing.assert_allclose(rig.deltas, proc.deltas, atol=2e-5)
    assert rig.identity_deltas.shape == (3, n_skin, 3)
    with pytest.warns(UnknownShapeWarning):
        whole = load_user_rig(folder)                                # the non-skin part kept
    assert whole.n_vertices == n_skin + 42 and whole.deltas.shape == (N_FACS, n_skin + 42, 3)


def test_train_reports_the_extras_in_one_line_and_strict_refuses(facexmodel, tmp_path, capsys):
    folder, _, n_skin = facexmodel
    common = ["train", "--config", str(ROOT / "configs" / "train" / "tiny.yaml"), "--rig", str(folder),
              "--keep-vertices", f"0:{n_skin}", "--rig-mix", "1", "--steps", "1", "--max-minutes", "0",
              "--no-progress"]
    assert main(common + ["--strict", "--out", str(tmp_path / "strict")]) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {folder}: unknown blendshape names PupilDilate_L, PupilDilate_R, "
                   "cheekRaiser_L, cheekRaiser_R (expected ICT names such as browDown_L or ARKit "
                   "names such as browDownLeft)\n")
    assert not (tmp_path / "strict" / "model.pt").exists()
    assert main(common + ["--out", str(tmp_path / "run")]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [f"warning: {folder}: left out 4 shapes that have no ICT or "
                                         "ARKit name: PupilDilate_L, PupilDilate_R, cheekRaiser_L, "
                                         "cheekRaiser_R"]
    assert "saved" in captured.out and (tmp_path / "run" / "model.pt").is_file()

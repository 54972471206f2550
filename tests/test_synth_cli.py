"""`retarget synth`, `retarget calibrate` and the preview sheets."""
import numpy as np
import pytest
import yaml

from data_synth.dataset import ShardReader
from retarget.calibrate import DEFAULT_RIG, compare, markdown_table, shape_stats, summary
from retarget.cli import main


def test_synth_writes_shards_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["synth", "--config", "configs/synth/tiny.yaml", "--out", str(out)]) == 0
    assert len(ShardReader(out)) == 3
    assert main(["synth", "--config", "configs/synth/tiny.yaml", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["synth", "--config", "configs/synth/tiny.yaml", "--out", str(out), "--overwrite"]) == 0


def test_synth_bad_config_is_a_one_line_error(tmp_path, capsys):
    cfg = yaml.safe_load(open("configs/synth/tiny.yaml"))
    cfg["expressions_per_identity"] = -4
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    assert main(["synth", "--config", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "expressions_per_identity" in err and str(path) in err
    assert main(["synth", "--config", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "o")]) == 2


def test_shape_stats_on_a_known_field():
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    delta = np.zeros((4, 3))
    delta[3] = [0, 0, 0.5]
    s = shape_stats(verts, faces, delta)
    assert s.max_cm == pytest.approx(0.5)
    assert s.moved_fraction == pytest.approx(1 / 6)     # vertex 3 is in one of the two triangles
    assert np.allclose(s.direction, [0, 0, 1])


@pytest.mark.skipif(not DEFAULT_RIG.is_file(), reason="shared real rig not present")
def test_calibration_table_against_the_real_rig():
    rows = compare(DEFAULT_RIG, n_vertices=4000)
    assert len(rows) == 51
    table = markdown_table(rows)
    assert table.count("\n") == 52 and "jawOpen" in table
    s = summary(rows)
    assert s["magnitude_within_0.5_2x"] >= 45 and s["direction_cosine_gt_0.7"] >= 45
    jaw = next(r for r in rows if r.arkit == "jawOpen")
    assert 0.7 < jaw.ratio < 1.4 and jaw.cosine > 0.9


def test_preview_sheets_render():
    pytest.importorskip("moderngl")
    from retarget import synth_preview
    from retarget.render import Renderer
    try:
        Renderer(8)
    except Exception as e:   # no EGL on this machine
        pytest.skip(f"offscreen rendering unavailable: {e}")
    for source in synth_preview.SOURCES:
        rig = synth_preview.preview_rig(source, 0, n_vertices=600, crop="face")
        img = synth_preview.shapes_sheet(rig, size=48)
        assert img.ndim == 3 and img.shape[2] == 3 and img.max() > 0.5
        seg = synth_preview.segments_sheet(source, 0, n_vertices=600, size=48)
        assert seg.shape[2] == 3 and seg.max() > 0.5

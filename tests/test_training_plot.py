"""The validation-curve plot of training logs."""
from pathlib import Path

from retarget.training_plot import main, validation_points

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "retarget" / "checkpoints" / "default_train_log.csv"


def test_points_are_the_validated_rows(tmp_path):
    pts = validation_points(LOG)
    rows = [line for line in LOG.read_text().splitlines()[1:] if not line.endswith(",,,")]
    assert len(pts) == len(rows) > 3 and all(h > 0 and v > 0 for h, v in pts)
    assert pts == sorted(pts, key=lambda p: p[0])


def test_plot_written_and_bad_logs_refused(tmp_path, capsys):
    out = tmp_path / "val.png"
    assert main([str(out), f"bundled={LOG}"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    assert main([str(tmp_path / "y.png"), str(bad)]) == 2
    assert "not a train_log.csv" in capsys.readouterr().err
    assert not (tmp_path / "y.png").exists()

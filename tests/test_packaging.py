"""Shipped configs: found by name, from a checkout and from a built wheel."""
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from retarget.config import configs_dir, find_config
from retarget.errors import RetargetError

ROOT = Path(__file__).resolve().parents[1]


def test_configs_are_found_by_file_by_name_and_by_checkout_path(tmp_path, monkeypatch):
    assert configs_dir() == ROOT / "configs"
    assert find_config("no_skinning", "train") == ROOT / "configs/train/no_skinning.yaml"
    assert find_config("tiny.yaml", "eval") == ROOT / "configs/eval/tiny.yaml"
    mine = tmp_path / "mine.yaml"
    mine.write_text("model: {preset: tiny}\n")
    assert find_config(str(mine), "train") == mine
    # the README's relative paths work from any folder (e.g. after a pip install)
    monkeypatch.chdir(tmp_path)
    assert find_config("configs/train/default.yaml", "train") == ROOT / "configs/train/default.yaml"
    with pytest.raises(RetargetError, match=r"nosuch: no such train config file .*no_skinning"):
        find_config("nosuch", "train")
    # a missing file in another folder is an error, not silently a shipped config of that name
    with pytest.raises(RetargetError, match="elsewhere/default.yaml: no such train config"):
        find_config(str(tmp_path / "elsewhere" / "default.yaml"), "train")


@pytest.mark.slow
def test_the_wheel_ships_the_configs_and_the_bundled_checkpoint(tmp_path):
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                          "-q", "-w", str(tmp_path), str(ROOT)], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    (wheel,) = tmp_path.glob("retarget-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"retarget/configs/{p.relative_to(ROOT / 'configs')}"
               for p in (ROOT / "configs").glob("*/*.yaml")}
    assert shipped and shipped <= names, sorted(shipped - names)
    assert "retarget/checkpoints/default.pt" in names
    assert "retarget/commands/eval.py" in names and "nets/model.py" in names

"""train.data_workers: samples made ahead by worker processes are the in-process pool's, so
training with workers ends at the same parameters; a worker's failure reaches the trainer."""
from pathlib import Path

import numpy as np
import pytest
import torch

from retarget.errors import RetargetError
from retarget.prefetch import PrefetchPool
from retarget.train import Trainer, load_config, model_cfg
from retarget.training_data import make_pool

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "train" / "tiny.yaml"


def tiny_mix_cfg(steps: int = 4) -> dict:
    """The tiny config with realistic heads beside the procedural ones and half the sources
    given their neutral, so that every kind of sample goes through the workers."""
    cfg = load_config(TINY)
    cfg["train"]["steps"] = steps
    cfg["data"]["sources"] = {"procedural": 0.5, "makehuman": 0.5}
    cfg["data"]["makehuman"]["tessellations"] = [{"n_vertices": 500, "kind": "decimated", "crop": "head"}]
    return cfg


def assert_same_group(a, b) -> None:
    np.testing.assert_array_equal(a.gt_dv, b.gt_dv)
    np.testing.assert_array_equal(a.target.mesh.vertices, b.target.mesh.vertices)
    np.testing.assert_array_equal(a.target.basis, b.target.basis)
    assert len(a.sources) == len(b.sources)
    for s, t in zip(a.sources, b.sources):
        assert s.kind == t.kind
        for name in ("feat", "image", "weights"):
            np.testing.assert_array_equal(getattr(s, name), getattr(t, name))
        assert (s.neutral is None) == (t.neutral is None)
        if s.neutral is not None:
            np.testing.assert_array_equal(s.neutral, t.neutral)
        np.testing.assert_array_equal(s.entry.mesh.vertices, t.entry.mesh.vertices)


def test_workers_give_the_in_process_pools_samples_in_order_and_after_a_jump():
    cfg = tiny_mix_cfg()
    mc = model_cfg(cfg)
    local = make_pool(cfg["data"], mc, 3)
    pool = PrefetchPool(cfg["data"], mc, 3, workers=2)
    try:
        for step in (0, 1, 2, 3, 7, 8):          # 3 -> 7: the schedule starts again at 7
            assert_same_group(pool.sample(step), local.sample(step))
        with pytest.raises(ValueError, match="rank 0"):
            pool.sample(9, rank=1)
    finally:
        pool.close()
    assert not pool.procs


def test_training_with_workers_ends_at_the_same_parameters(tmp_path):
    runs = {}
    for workers in (0, 2):
        cfg = tiny_mix_cfg(steps=4)
        cfg["train"]["data_workers"] = workers
        trainer = Trainer(cfg, tmp_path / f"w{workers}", progress=False)
        assert isinstance(trainer.pool, PrefetchPool) == bool(workers)
        trainer.run()
        runs[workers] = trainer.model.state_dict()
    for k in runs[0]:
        assert torch.equal(runs[0][k], runs[2][k]), k


def test_a_workers_error_is_raised_with_its_traceback():
    cfg = load_config(TINY)
    data = {**cfg["data"], "tessellations": [{"n_vertices": 400, "kind": "no-such-layout", "region": "full"}]}
    pool = PrefetchPool(data, model_cfg(cfg), 0, workers=1)
    try:
        with pytest.raises(RetargetError, match=r"(?s)training data worker failed .*no-such-layout"):
            pool.sample(0)
    finally:
        pool.close()


def test_data_workers_option_and_its_bounds(tmp_path):
    import argparse

    from retarget.commands import train as train_cmd
    p = argparse.ArgumentParser()
    train_cmd.add_arguments(p)
    cfg, _ = train_cmd.training_config(p.parse_args(["--config", str(TINY), "--out", "x",
                                                      "--data-workers", "3"]))
    assert cfg["train"]["data_workers"] == 3
    assert load_config(TINY)["train"]["data_workers"] == 0
    with pytest.raises(RetargetError, match="--data-workers"):
        train_cmd.training_config(p.parse_args(["--config", str(TINY), "--out", "x",
                                                "--data-workers", "-1"]))
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"base: {TINY}\ntrain: {{data_workers: 1.5}}\n")
    with pytest.raises(RetargetError, match=r"bad\.yaml: train\.data_workers must be an integer"):
        load_config(bad)
    with pytest.raises(ValueError, match="at least one worker"):
        PrefetchPool({}, None, 0, workers=0)

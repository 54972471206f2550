"""Segmentation, weight sampling and the sharded dataset (data_synth.segmentation/sampling/dataset)."""
import numpy as np
import pytest
import yaml

from data_synth.dataset import ShardReader, generate_items, load_config, validate_config, write_shards
from data_synth.sampling import sample_weights, smooth_sequence
from data_synth.segmentation import SEGMENT_LEVELS, SEGMENT_NAMES, segment_labels
from data_synth.tessellate import tessellate


@pytest.fixture(scope="module")
def full_head():
    return tessellate(4000, kind="adaptive", region="full", holes=True)


@pytest.mark.parametrize("level", SEGMENT_LEVELS)
def test_every_region_is_present_on_a_full_head(full_head, level):
    lab = segment_labels(full_head.uv, level)
    assert lab.dtype == np.int64 and lab.shape == (len(full_head.uv),)
    assert len(SEGMENT_NAMES[level]) == level
    assert np.array_equal(np.unique(lab), np.arange(level))


def test_levels_are_nested_and_sided(full_head):
    fine = segment_labels(full_head.uv, 24)
    for level in (20, 14, 6):
        coarse = segment_labels(full_head.uv, level)
        for f in range(24):               # each fine region falls in exactly one coarse region
            assert len(np.unique(coarse[fine == f])) == 1
    lab = segment_labels(full_head.uv, 20)
    names = SEGMENT_NAMES[20]
    mirrored = segment_labels(full_head.uv * [-1, 1], 20)
    for i, n in enumerate(names):
        if n.endswith("_L"):
            assert np.all(full_head.uv[lab == i, 0] >= 0)
            assert np.array_equal(mirrored == names.index(n[:-1] + "R"), lab == i)
    with pytest.raises(ValueError, match="n_segments"):
        segment_labels(full_head.uv, 12)


@pytest.mark.parametrize("mode", ["uniform", "onehot", "sparse", "neutral", "subtle", "mixed", "calm"])
def test_sample_weights(mode):
    w = sample_weights(np.random.default_rng(0), 400, mode)
    assert w.shape == (400, 53) and w.min() >= 0 and w.max() <= 1
    active = (w > 0).sum(1)
    if mode == "onehot":
        assert (active == 1).all() and np.allclose(w.max(1), 1)
    if mode == "sparse":
        assert active.min() >= 1 and active.max() <= 5
    if mode == "neutral":
        assert (active == 0).all()
    if mode == "subtle":
        assert active.min() >= 1 and active.max() <= 5 and w.max() <= 0.3
    if mode == "mixed":
        assert (active == 1).any() and (active == 53).any() and ((active > 1) & (active <= 5)).any()
        assert active.min() >= 1
    if mode == "calm":                  # about 10 % neutral and 15 % subtle frames besides "mixed"'s
        assert 0.05 < (active == 0).mean() < 0.15 and (active == 53).any()
        assert 0.1 < ((active > 0) & (w.max(1) <= 0.3)).mean() < 0.25
    assert np.array_equal(w, sample_weights(np.random.default_rng(0), 400, mode))


def test_smooth_sequence_is_smooth_and_bounded():
    seq = smooth_sequence(np.random.default_rng(1), 300, fps=30)
    assert seq.shape == (300, 53) and seq.min() >= 0 and seq.max() <= 1 and seq.max() > 0.2
    jump = np.abs(np.diff(seq, axis=0)).max()
    rough = np.abs(np.diff(np.random.default_rng(1).random((300, 53)), axis=0)).max()
    assert jump < 0.2 < rough


def test_shards_round_trip(tmp_path):
    cfg = load_config("configs/synth/tiny.yaml")
    items = list(generate_items(cfg))
    paths = write_shards(tmp_path / "ds", iter(items), cfg["shard_size"], config=cfg)
    assert len(paths) == 2 and not list((tmp_path / "ds").glob("*.tmp"))
    reader = ShardReader(tmp_path / "ds")
    assert reader.config == cfg
    assert len(reader) == cfg["n_identities"]
    for item, back in zip(items, reader):
        assert set(back) == set(item)
        for k in item:
            assert np.array_equal(item[k], back[k])
        w, x = back["weights"], back["expressions"]
        assert np.allclose(x, back["neutral"] + np.tensordot(w, back["deltas"], axes=(1, 0)), atol=1e-5)
    again = list(generate_items(cfg))
    assert all(np.array_equal(a["expressions"], b["expressions"]) for a, b in zip(items, again))


@pytest.mark.parametrize("key,value", [("n_identities", 0), ("weights", "gaussian"), ("split", "dev"),
                                        ("n_segments", 7), ("bogus_key", 1)])
def test_bad_config_values_name_the_key(tmp_path, key, value):
    cfg = yaml.safe_load(open("configs/synth/tiny.yaml"))
    cfg[key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ValueError, match=key):
        load_config(path)


def test_bad_tessellation_spec_names_the_key():
    with pytest.raises(ValueError, match=r"tessellations\[0\].kind"):
        validate_config({"tessellations": [{"n_vertices": 500, "kind": "voronoi"}]})


def test_default_config_is_valid():
    cfg = load_config("configs/synth/default.yaml")
    assert cfg["n_identities"] > 100 and len(cfg["tessellations"]) >= 4

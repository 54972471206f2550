"""Training on the mix of procedural and realistic (MakeHuman) rigs."""
from pathlib import Path

import numpy as np
import pytest

from data_synth.facs import FACS_INDEX
from data_synth.makehuman.expressions import SURROGATE_NAMES
from retarget.errors import RetargetError
from retarget.train import Trainer, load_config
from retarget.training_data import TargetPool, validation_entries

ROOT = Path(__file__).resolve().parents[1]


def mix_cfg(share=0.5, expressions=None):
    cfg = load_config(ROOT / "configs" / "train" / "tiny.yaml")
    cfg["data"]["sources"] = {"procedural": 1.0 - share, "makehuman": share}
    cfg["data"]["makehuman"]["tessellations"] = [
        {"n_vertices": 400, "kind": "decimated", "crop": "face"},
        {"n_vertices": 500, "kind": "jittered", "crop": "bust"}]
    if expressions:
        cfg["data"]["makehuman"]["expressions"] = expressions
    return cfg


def test_pool_draws_both_sources_with_exact_ground_truth():
    cfg = mix_cfg(0.5)
    from retarget.train import model_cfg
    pool = TargetPool(cfg["data"], model_cfg(cfg), seed=0)
    kinds = {pool.identity_source(i) for i in range(8)}
    assert kinds == {"procedural", "makehuman"}
    slot = next(s for s in range(cfg["data"]["pool_size"])
                if pool.identity_source(pool.slot_key(s, 0)[0]) == "makehuman")
    a, b = pool.slot(slot, 0)
    assert a.rig.uv is None and a.rig.identity is None and a.present.all()
    assert a.rig.correspondence.shape[1] == b.rig.correspondence.shape[1]
    g1, g2 = pool.sample(3), pool.sample(3)
    assert np.array_equal(g1.gt_dv, g2.gt_dv)          # deterministic: resume is exact
    w = np.stack([s.weights for s in g1.sources])
    assert np.allclose(g1.gt_dv, np.einsum("sk,kvc->svc", w, g1.target.basis), atol=1e-5)


def test_units_rigs_zero_the_shapes_they_lack():
    cfg = mix_cfg(1.0, {"arkit": 0.0, "units": 1.0})
    from retarget.train import model_cfg
    pool = TargetPool(cfg["data"], model_cfg(cfg), seed=0)
    group = pool.sample(0)
    assert group.target.present is not None and not group.target.present.all()
    for s in group.sources:
        assert np.all(s.weights[~group.target.present] == 0)
    val = validation_entries(cfg["data"], model_cfg(cfg), seed=0)
    assert all(np.all(w[:, ~e.present] == 0) for e, w in val)


def test_units_full_rigs_have_every_shape_and_a_zero_share_changes_no_draw():
    from retarget.train import model_cfg
    cfg = mix_cfg(1.0, {"arkit": 0.0, "units": 0.0, "units_full": 1.0})
    group = TargetPool(cfg["data"], model_cfg(cfg), seed=0).sample(0)
    assert group.target.present.all()
    surrogate = [FACS_INDEX[n] for n in SURROGATE_NAMES]
    assert any(np.any(s.weights[surrogate] > 0) for g in pool_groups(cfg, 2) for s in g.sources)
    # a source given share 0 leaves the other sources' draws as they were without it
    a, b = mix_cfg(1.0, {"arkit": 0.6, "units": 0.4}), mix_cfg(1.0, {"arkit": 0.6, "units": 0.4})
    b["data"]["makehuman"]["expressions"]["units_full"] = 0.0
    ga, gb = pool_groups(a, 3), pool_groups(b, 3)
    assert all(np.array_equal(x.gt_dv, y.gt_dv) for x, y in zip(ga, gb))


def pool_groups(cfg: dict, n: int) -> list:
    from retarget.train import model_cfg
    pool = TargetPool(cfg["data"], model_cfg(cfg), seed=0)
    return [pool.sample(i) for i in range(n)]


def test_bad_source_shares_are_refused():
    cfg = mix_cfg(0.5)
    cfg["data"]["sources"] = {"procedural": 0.0, "scans": 1.0}
    from retarget.train import model_cfg
    with pytest.raises(RetargetError, match="data.sources"):
        TargetPool(cfg["data"], model_cfg(cfg), seed=0)


def test_a_few_mixed_training_steps_run(tmp_path):
    cfg = mix_cfg(0.5)
    cfg["train"]["steps"] = 3
    Trainer(cfg, tmp_path, progress=False).run()
    assert (tmp_path / "model.pt").is_file()
    log = (tmp_path / "train_log.csv").read_text()
    assert "val_mse_mm2" in log.splitlines()[0]


def test_shipped_mix_configs_load():
    for name in ("mix", "mix_no_arkit"):
        cfg = load_config(ROOT / "configs" / "train" / f"{name}.yaml")
        assert cfg["data"]["sources"]["makehuman"] == 0.5
    withheld = load_config(ROOT / "configs" / "train" / "mix_no_arkit.yaml")
    assert withheld["data"]["makehuman"]["expressions"] == {"arkit": 0.0, "units": 1.0, "units_full": 0.0}
    full = load_config(ROOT / "configs" / "train" / "realistic_units_full.yaml")
    assert full["data"]["makehuman"]["expressions"] == {"arkit": 0.0, "units": 0.0, "units_full": 1.0}


def _without(cfg: dict, section: str, key: str) -> dict:
    """A copy of ``cfg`` with ``cfg[section][key]`` removed."""
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in cfg.items()}
    out[section].pop(key, None)
    return out


def test_stage6_study_configs_change_one_switch_of_the_bundled_design():
    """The two studies of RESULTS' "Stage 6" differ from realistic_rig.yaml in one setting each:
    the sources' share of MakeHuman heads, and the share of sources given their neutral."""
    base = load_config(ROOT / "configs" / "train" / "realistic_rig.yaml")
    mh75 = load_config(ROOT / "configs" / "train" / "realistic_rig_mh75.yaml")
    share25 = load_config(ROOT / "configs" / "train" / "realistic_rig_share25.yaml")
    assert base["data"]["sources"] == {"procedural": 0.5, "makehuman": 0.5}
    assert mh75["data"]["sources"] == {"procedural": 0.25, "makehuman": 0.75}
    assert (base["data"]["source_neutral_share"], share25["data"]["source_neutral_share"]) == (0.5, 0.25)
    assert _without(mh75, "data", "sources") == _without(base, "data", "sources")
    assert (_without(share25, "data", "source_neutral_share")
            == _without(base, "data", "source_neutral_share"))


def test_relative_rig_config_changes_only_l_rig_of_the_bundled_run():
    """realistic_rig_relative.yaml (stage 12's study) is realistic_rig_partial.yaml, the bundled
    run's config, with L_rig relative to each shape's size."""
    base = load_config(ROOT / "configs" / "train" / "realistic_rig_partial.yaml")
    rel = load_config(ROOT / "configs" / "train" / "realistic_rig_relative.yaml")
    assert (base["loss"]["rig_relative"], rel["loss"]["rig_relative"]) == (0.0, 0.05)
    assert _without(rel, "loss", "rig_relative") == _without(base, "loss", "rig_relative")


def test_heavy_rig_config_changes_only_the_weight_of_relative_l_rig():
    """realistic_rig_heavy.yaml (stages 13 to 15, the bundled run) is realistic_rig_relative.yaml with L_rig ten times as
    heavy, the rest of the bundled run's config unchanged."""
    rel = load_config(ROOT / "configs" / "train" / "realistic_rig_relative.yaml")
    heavy = load_config(ROOT / "configs" / "train" / "realistic_rig_heavy.yaml")
    assert (rel["loss"]["rig"], heavy["loss"]["rig"]) == (10.0, 100.0)
    assert heavy["loss"]["rig_relative"] == 0.05
    assert _without(heavy, "loss", "rig") == _without(rel, "loss", "rig")


def test_heavier_rig_config_changes_only_the_weight_of_l_rig():
    """realistic_rig_heavier.yaml (stage 16) is the bundled run's config with L_rig three times as
    heavy."""
    heavy = load_config(ROOT / "configs" / "train" / "realistic_rig_heavy.yaml")
    heavier = load_config(ROOT / "configs" / "train" / "realistic_rig_heavier.yaml")
    assert (heavy["loss"]["rig"], heavier["loss"]["rig"]) == (100.0, 300.0)
    assert _without(heavier, "loss", "rig") == _without(heavy, "loss", "rig")


@pytest.mark.parametrize("bundled", ["realistic_rig_heavy", "realistic_rig_heavier"])
def test_no_neutral_ablations_differ_from_the_bundled_configs_only_in_the_encoder(bundled):
    """realistic_rig_heavy_no_neutral.yaml and realistic_rig_heavier_no_neutral.yaml (the no_neutral
    ablation at the bundled budget: stages 13-15, 16-17) are the bundled run's configs with the
    paper's expression encoder: same data, loss, schedule."""
    heavy = load_config(ROOT / "configs" / "train" / f"{bundled}.yaml")
    ablation = load_config(ROOT / "configs" / "train" / f"{bundled}_no_neutral.yaml")
    assert (heavy["model"]["neutral_channels"], ablation["model"]["neutral_channels"]) == (True, False)
    assert _without(ablation, "model", "neutral_channels") == _without(heavy, "model", "neutral_channels")


def test_descriptor_configs_change_only_the_descriptor_and_l_corr():
    """realistic_rig_descriptor.yaml adds 16 skinning descriptor channels to realistic_rig_heavier;
    realistic_rig_corr.yaml adds L_corr to that."""
    heavier = load_config(ROOT / "configs" / "train" / "realistic_rig_heavier.yaml")
    desc = load_config(ROOT / "configs" / "train" / "realistic_rig_descriptor.yaml")
    corr = load_config(ROOT / "configs" / "train" / "realistic_rig_corr.yaml")
    assert (heavier["model"].get("skin_descriptor", 0), desc["model"]["skin_descriptor"]) == (0, 16)
    assert _without(desc, "model", "skin_descriptor") == _without(heavier, "model", "skin_descriptor")
    assert (desc["loss"]["corr"], corr["loss"]["corr"]) == (0.0, 0.05)
    assert _without(corr, "loss", "corr") == _without(desc, "loss", "corr")


def test_realistic_targets_carry_their_template_positions_and_l_corr_trains_on_them():
    import torch
    from nets.losses import TEMPLATE_SPAN, correspondence_loss
    from retarget.train import group_losses, model_cfg
    from retarget.training_data import base_template, template_positions

    cfg = mix_cfg(0.5)
    cfg["model"] = {"preset": "tiny", "decoder": "basis", "skin_descriptor": 4}
    pool = TargetPool(cfg["data"], model_cfg(cfg), seed=0)
    groups = (pool.sample(i) for i in range(200))
    real = proc = None
    while real is None or proc is None:
        g = next(groups)
        if g.target.rig.correspondence is None:
            proc = proc or g
        else:
            real = real or g
    assert proc.target.template is None
    t = real.target.template
    assert t.shape == (len(real.target.rig.neutral), 3)
    np.testing.assert_allclose(t, real.target.rig.correspondence @ base_template(), atol=1e-4)
    # the template is the base bust in its own face frame: the head about 16 units wide
    head = base_template()[:4326]
    assert 12 < head[:, 0].max() - head[:, 0].min() < 20
    exact = torch.from_numpy(0.5 + t / TEMPLATE_SPAN)
    assert float(correspondence_loss(exact, torch.from_numpy(t))) < 1e-8
    assert float(correspondence_loss(exact + 0.01, torch.from_numpy(t))) > 0.1
    assert template_positions(proc.target.rig) is None

    from nets.model import NFSModel
    torch.manual_seed(0)
    model = NFSModel(model_cfg(cfg))
    loss_cfg = {**load_config(ROOT / "configs" / "train" / "tiny.yaml")["loss"], "corr": 1.0}
    rng = np.random.default_rng(0)
    out = group_losses(model, real, loss_cfg, 200, rng, "cpu")
    assert torch.isfinite(out["L_corr"]) and out["L_corr"] > 0
    out["L_corr"].backward()
    grad = model.skinning_encoder.last.weight.grad
    assert grad[model.cfg.n_segments:model.cfg.n_segments + 3].abs().sum() > 0   # channels 0-2 train
    assert grad[model.cfg.n_segments + 3:].abs().sum() == 0                      # the others do not
    assert "L_corr" not in group_losses(model, proc, loss_cfg, 200, rng, "cpu")
    assert "L_corr" not in group_losses(model, real, {**loss_cfg, "corr": 0.0}, 200, rng, "cpu")

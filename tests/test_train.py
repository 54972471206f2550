"""The trainer on the tiny config: it learns, resumes exactly, runs under torchrun, fails clearly."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from retarget.errors import RetargetError
from retarget.train import Trainer, group_losses, load_checkpoint, load_config

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "train" / "tiny.yaml"


def tiny_cfg(steps=6):
    cfg = load_config(TINY)
    cfg["train"]["steps"] = steps
    return cfg


def test_config_errors_name_file_and_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("data: {pool_sise: 3}\n")
    with pytest.raises(RetargetError, match=r"bad\.yaml.*pool_sise"):
        load_config(bad)
    bad.write_text("model: {preset: huge}\n")
    with pytest.raises(RetargetError, match="bad.yaml: model"):
        load_config(bad)
    with pytest.raises(RetargetError, match="cannot read"):
        load_config(tmp_path / "missing.yaml")


def test_every_loss_term_is_finite_and_bp_br_change_gradients(tmp_path):
    cfg = tiny_cfg()
    trainer = Trainer(cfg, tmp_path, progress=False)
    group = trainer.pool.sample(0)
    rng = lambda: np.random.default_rng(0)  # noqa: E731
    losses = group_losses(trainer.model, group, cfg["loss"], 200, rng(), "cpu")
    for key in ("L_v", "L_n", "L_g", "L_ID", "L_Exp", "L_BP", "L_BR", "L_nll", "total"):
        assert torch.isfinite(losses[key]), key
        assert losses[key].item() >= 0

    def grads(loss_cfg):
        trainer.model.zero_grad()
        group_losses(trainer.model, group, loss_cfg, 200, rng(), "cpu")["total"].backward()
        return {n: p.grad.clone() for n, p in trainer.model.named_parameters() if p.grad is not None}

    base = grads(cfg["loss"])
    no_bp = grads({**cfg["loss"], "bp": 0.0})
    no_br = grads({**cfg["loss"], "br": 0.0})
    enc = [n for n in base if n.startswith("expression_encoder")]
    dec = [n for n in base if n.startswith("decoder")]
    assert any(not torch.allclose(base[n], no_bp[n]) for n in enc), "L_BP does not reach the encoder"
    assert any(not torch.allclose(base[n], no_br[n]) for n in dec), "L_BR does not reach the decoder"


def test_training_reduces_the_loss_and_resume_is_exact(tmp_path):
    full = Trainer(tiny_cfg(6), tmp_path / "full", progress=False)
    full.run()
    log = (tmp_path / "full" / "train_log.csv").read_text().splitlines()
    assert log[0].startswith("step,") and len(log) >= 3

    # interrupted after 3 steps, then resumed to 6: identical parameters
    half = Trainer(tiny_cfg(6), tmp_path / "half", progress=False)
    half.run(stop_at=3)
    resumed = Trainer(tiny_cfg(6), tmp_path / "half", progress=False)
    assert resumed.resume() and resumed.step == 3
    resumed.run()
    a, b = full.model.state_dict(), resumed.model.state_dict()
    for k in a:
        assert torch.allclose(a[k], b[k], atol=1e-6), k

    state = load_checkpoint(tmp_path / "full" / "model.pt")
    assert state["step"] == 6 and "optimizer" not in state


def test_overfitting_one_group_lowers_the_vertex_loss(tmp_path):
    cfg = tiny_cfg()
    trainer = Trainer(cfg, tmp_path, progress=False)
    group = trainer.pool.sample(0)
    opt = torch.optim.Adam(trainer.model.parameters(), lr=3e-3)
    first = None
    for _ in range(30):
        losses = group_losses(trainer.model, group, cfg["loss"], 0, np.random.default_rng(0), "cpu")
        opt.zero_grad()
        losses["total"].backward()
        opt.step()
        first = first if first is not None else losses["L_v"].item()
    assert losses["L_v"].item() < 0.5 * first


def test_tampered_checkpoint_is_refused(tmp_path):
    bad = tmp_path / "evil.pt"

    class Evil:
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    torch.save({"format": "retarget-checkpoint/1", "x": Evil()}, bad)
    with pytest.raises(RetargetError, match="evil.pt: holds pickled code .* and was refused"):
        load_checkpoint(bad)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"not a checkpoint")
    with pytest.raises(RetargetError, match="garbage.pt"):
        load_checkpoint(garbage)


@pytest.mark.slow
def test_two_gloo_processes_keep_identical_parameters(tmp_path):
    script = tmp_path / "ddp.py"
    script.write_text(f"""
import os, sys, torch, torch.distributed as dist
sys.path.insert(0, {str(ROOT)!r})
from retarget.train import Trainer, load_config, shutdown_distributed
cfg = load_config({str(TINY)!r}); cfg["train"].update(steps=10000, val_every=100000, max_minutes=0.5)
cfg["optim"]["warmup_steps"] = 0  # the learning rate follows the clock from the first step
t = Trainer(cfg, {str(tmp_path / 'run')!r}, progress=False)
t.run(stop_at=3)
flat = torch.cat([p.detach().reshape(-1) for p in t.model.parameters()])
out = [torch.zeros_like(flat) for _ in range(2)]
dist.all_gather(out, flat)
assert torch.equal(out[0], out[1]), "parameters diverged"
start = torch.cat([p.reshape(-1) for p in Trainer(cfg, {str(tmp_path / 'other')!r}, progress=False).model.parameters()])
assert not torch.equal(start, flat), "no training happened"
open({str(tmp_path)!r} + f"/rank{{dist.get_rank()}}.ok", "w").write("ok")
shutdown_distributed()
sys.stdout.flush(); sys.stderr.flush()
os._exit(0)  # skip interpreter finalisation, where gloo's worker threads can abort the process
""")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone",
                          "--nproc_per_node", "2", str(script)], capture_output=True, text=True,
                         env=env, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    # each rank leaves a marker file (their stdout lines can interleave)
    assert sorted(p.name for p in tmp_path.glob("rank*.ok")) == ["rank0.ok", "rank1.ok"]


def test_committed_configs_load_and_ablations_differ_from_default_only_where_named(tmp_path):
    from retarget.train import model_cfg
    configs = {p.stem: load_config(p) for p in (ROOT / "configs" / "train").glob("*.yaml")}
    assert {"default", "tiny", "paper", "no_skinning", "no_bp", "no_br", "seg6", "seg14", "seg24"} <= set(configs)
    default = configs["default"]
    assert model_cfg(configs["no_skinning"]).use_skinning is False
    assert configs["no_bp"]["loss"]["bp"] == 0.0 and configs["no_br"]["loss"]["br"] == 0.0
    for n in (6, 14, 24):
        assert model_cfg(configs[f"seg{n}"]).n_segments == n
    for name in ("no_skinning", "no_bp", "no_br", "seg6", "seg14", "seg24"):
        assert configs[name]["data"] == default["data"] and configs[name]["train"] == default["train"]
    loop = tmp_path / "loop.yaml"
    loop.write_text("base: loop.yaml\n")
    with pytest.raises(RetargetError, match="includes itself"):
        load_config(loop)


def _train_cmd(out, steps=6, extra=()):
    cfg = out.parent / f"{out.name}.yaml"
    cfg.write_text(f"base: {TINY}\ntrain: {{steps: {steps}, ckpt_minutes: 0.0, val_every: 100}}\n")
    return [sys.executable, "-m", "retarget.cli", "train", "--config", str(cfg), "--out", str(out),
            "--no-progress", *extra]


@pytest.mark.slow
@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT"])
def test_interrupted_run_resumes_to_the_same_parameters(tmp_path, sig):
    import signal
    import time

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    # a tiny step takes ~75 ms: the checkpoint is seen in the first half of the run, so the signal
    # lands well before its end even when the poll or the machine is slow
    steps = 40
    subprocess.run(_train_cmd(tmp_path / "full", steps=steps), check=True, env=env, cwd=ROOT,
                   capture_output=True)
    proc = subprocess.Popen(_train_cmd(tmp_path / "cut", steps=steps), env=env, cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    last = tmp_path / "cut" / "last.pt"
    while time.monotonic() < deadline and proc.poll() is None:  # wait for a mid-run checkpoint
        if last.exists() and 2 <= torch.load(last, weights_only=True)["step"] < steps // 2:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(getattr(signal, sig))
    _, err = proc.communicate(timeout=120)
    if sig == "SIGINT":  # Ctrl-C: finishes the step, saves, exits cleanly
        assert proc.returncode == 0 and "Traceback" not in err, err[-2000:]
    stopped_at = torch.load(last, weights_only=True)["step"]
    assert stopped_at < steps
    res = subprocess.run(_train_cmd(tmp_path / "cut", steps=steps, extra=("--resume",)), env=env, cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert f"at step {stopped_at}" in res.stdout
    a = load_checkpoint(tmp_path / "full" / "model.pt")["model"]
    b = load_checkpoint(tmp_path / "cut" / "model.pt")["model"]
    for k in a:
        assert torch.allclose(a[k], b[k], atol=1e-6), k


def test_train_command_overrides_the_step_and_time_budget():
    import argparse
    from retarget.commands import train as train_cmd
    p = argparse.ArgumentParser()
    train_cmd.add_arguments(p)
    cfg, _ = train_cmd.training_config(p.parse_args(
        ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x", "--steps", "1500",
         "--max-minutes", "0", "--lr", "2e-4"]))
    assert cfg["train"]["steps"] == 1500 and cfg["train"]["max_minutes"] == 0
    assert cfg["optim"]["lr"] == 2e-4
    cfg, _ = train_cmd.training_config(p.parse_args(
        ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x"]))
    assert cfg["train"] == load_config(ROOT / "configs/train/default.yaml")["train"]
    cfg, _ = train_cmd.training_config(p.parse_args(
        ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x", "--seed", "3"]))
    assert cfg["train"]["seed"] == 3
    with pytest.raises(RetargetError, match="--seed"):
        train_cmd.training_config(p.parse_args(
            ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x", "--seed", "-1"]))
    with pytest.raises(RetargetError, match="--lr"):
        train_cmd.training_config(p.parse_args(
            ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x", "--lr", "0"]))
    with pytest.raises(RetargetError, match="--max-minutes"):
        train_cmd.training_config(p.parse_args(
            ["--config", str(ROOT / "configs/train/default.yaml"), "--out", "x", "--max-minutes", "-1"]))


def test_rig_loss_term_reaches_the_decoder_and_decodes_the_rigs_shapes_only(tmp_path):
    from retarget.train import RIG_SHAPES_MLP, rig_shapes
    cfg = tiny_cfg()
    trainer = Trainer(cfg, tmp_path, progress=False)
    group = trainer.pool.sample(0)
    rng = lambda: np.random.default_rng(0)  # noqa: E731
    assert "L_rig" not in group_losses(trainer.model, group, cfg["loss"], 200, rng(), "cpu")

    def grads(loss_cfg):
        trainer.model.zero_grad()
        out = group_losses(trainer.model, group, loss_cfg, 200, rng(), "cpu")
        out["total"].backward()
        return out, {n: p.grad.clone() for n, p in trainer.model.named_parameters()
                     if p.grad is not None and n.startswith("decoder")}

    with_rig, g_rig = grads({**cfg["loss"], "rig": 10.0})
    _, g_base = grads(cfg["loss"])
    assert torch.isfinite(with_rig["L_rig"]) and with_rig["L_rig"] > 0
    assert any(not torch.allclose(g_rig[n], g_base[n]) for n in g_base), "L_rig misses the decoder"
    present = np.zeros(53, bool)
    present[[0, 5, 9]] = True
    basis_model = type("M", (), {"cfg": type("C", (), {"n_facs": 53, "decoder": "basis"})})()
    mlp_model = type("M", (), {"cfg": type("C", (), {"n_facs": 53, "decoder": "mlp"})})()
    assert rig_shapes(basis_model, None, rng()).tolist() == list(range(53))
    assert rig_shapes(basis_model, present, rng()).tolist() == [0, 5, 9]
    assert rig_shapes(mlp_model, present, rng()).tolist() == [0, 5, 9]
    drawn = rig_shapes(mlp_model, None, rng())
    assert len(drawn) == RIG_SHAPES_MLP == len(set(drawn.tolist()))


def test_solve_term_reaches_the_decoder_and_solves_only_the_rigs_shapes(tmp_path, monkeypatch):
    import nets.losses as L
    cfg = tiny_cfg()
    trainer = Trainer(cfg, tmp_path, progress=False)
    group = trainer.pool.sample(0)
    rng = lambda: np.random.default_rng(0)  # noqa: E731
    assert "L_solve" not in group_losses(trainer.model, group, cfg["loss"], 200, rng(), "cpu")
    trainer.model.zero_grad()
    out = group_losses(trainer.model, group, {**cfg["loss"], "solve": 1.0}, 200, rng(), "cpu")
    out["total"].backward()
    assert torch.isfinite(out["L_solve"]) and out["L_solve"] > 0
    assert any(p.grad is not None and p.grad.abs().sum() > 0
               for n, p in trainer.model.named_parameters() if n.startswith("decoder"))
    seen = {}
    monkeypatch.setattr(L, "solve_loss", lambda *a, **k: seen.setdefault("w", a[5]).sum() * 0)
    from retarget.train import solve_term
    present = np.zeros(53, bool)
    present[[0, 5, 9]] = True
    solve_term(None, None, None, None, torch.zeros(53, 4, 3), present, None,
               {"solve_frames": 6, "solve_ridge": 0.01}, rng())
    assert seen["w"].shape == (6, 53) and not seen["w"][:, ~torch.from_numpy(present)].any()
    assert seen["w"][:, torch.from_numpy(present)].any()


def test_rig_targets_add_other_heads_to_l_rig_and_leave_the_rest_of_the_group(tmp_path):
    from retarget.train import extra_rig_loss
    cfg = tiny_cfg()
    one = Trainer(cfg, tmp_path / "one", progress=False).pool.sample(3)
    cfg["data"]["rig_targets"] = 3
    trainer = Trainer(cfg, tmp_path / "three", progress=False)
    group = trainer.pool.sample(3)
    assert one.rig_targets == () and len(group.rig_targets) == 2
    assert all(e is not group.target for e in group.rig_targets)
    assert np.array_equal(group.target.basis, one.target.basis)
    assert np.array_equal(group.gt_dv, one.gt_dv)   # the sources and their ground truth unchanged
    loss_cfg = {**cfg["loss"], "rig": 10.0}
    with_extra = group_losses(trainer.model, group, loss_cfg, 200, np.random.default_rng(0), "cpu")
    alone = group_losses(trainer.model, one, loss_cfg, 200, np.random.default_rng(0), "cpu")
    assert torch.allclose(with_extra["L_v"], alone["L_v"])
    extras = [extra_rig_loss(trainer.model, e, loss_cfg, 200, np.random.default_rng(1), "cpu")
              for e in group.rig_targets]
    assert all(torch.isfinite(x) and x > 0 for x in extras)
    # the mean over the three heads: the extra heads move L_rig
    assert not torch.allclose(with_extra["L_rig"], alone["L_rig"])
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"base: {TINY}\ndata: {{rig_targets: 0}}\n")
    with pytest.raises(RetargetError, match="rig_targets"):
        load_config(bad)


def test_free_dims_dropout_zeroes_the_dims_past_the_weights_of_some_sources():
    from retarget.train import free_dims_dropout
    z = torch.rand(400, 128, requires_grad=True)
    assert free_dims_dropout(z, 53, 0.0, np.random.default_rng(0)) is z
    out = free_dims_dropout(z, 53, 0.5, np.random.default_rng(0))
    dropped = (out[:, 53:] == 0).all(1)
    assert torch.equal(out[:, :53], z[:, :53]) and 120 < int(dropped.sum()) < 280
    assert torch.equal(out[~dropped], z[~dropped])
    out.sum().backward()                      # the weights keep their gradient in every source
    assert (z.grad[:, :53] == 1).all() and (z.grad[dropped, 53:] == 0).all()
    assert (free_dims_dropout(z, 53, 1.0, np.random.default_rng(1))[:, 53:] == 0).all()


def small_head(cfg):
    """A 300-vertex procedural test head prepared for a model of ``cfg``: (rig, PreparedMesh,
    (feat, img, ops) torch inputs on the CPU)."""
    from data_synth.identity import sample_identity
    from data_synth.rig import build_rig
    from data_synth.tessellate import tessellate
    from retarget.prepare import IMAGE_CHANNELS, prepare_mesh

    rig = build_rig(sample_identity(0, split="test"), tessellate(n_vertices=300, kind="regular"))
    mesh = prepare_mesh(rig.neutral, rig.faces, cfg.k_eig, cfg.image_size,
                        IMAGE_CHANNELS[cfg.image_channels])
    return rig, mesh, mesh.torch_inputs("cpu")


def test_warm_start_copies_what_fits_widens_the_expression_input_and_zeroes_a_new_decoder(tmp_path):
    from nets.model import NEUTRAL_CHANNEL_DIM, NFSConfig, NFSModel
    from retarget.checkpoint import warm_start

    torch.manual_seed(0)
    old = NFSModel(NFSConfig.preset("tiny"))
    torch.manual_seed(1)
    new = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2,
                                    neutral_channels=True))
    report = warm_start(new, old)
    assert report["widened"] == ["expression_encoder.first.weight"]
    assert report["fresh"] and all(n.startswith("decoder.") for n in report["fresh"])
    assert torch.equal(new.identity_encoder.last.weight, old.identity_encoder.last.weight)
    assert torch.equal(new.cnn.state_dict()[next(iter(new.cnn.state_dict()))],
                       old.cnn.state_dict()[next(iter(old.cnn.state_dict()))])
    cfg = old.cfg
    rig, mesh, (feat, img, ops) = small_head(cfg)
    with torch.no_grad():
        c = old.image_code(img)[0]
        assert torch.equal(new.image_code(img)[0], c)
        # no neutral (channels zero, flag 1): the widened encoder computes what the old one did
        torch.testing.assert_close(new.encode_expression(feat, c, ops),
                                   old.encode_expression(feat, c, ops), rtol=1e-5, atol=1e-6)
        codes = new.encode_target(feat, c, ops)
        z = torch.rand(new.cfg.code_dim)
        assert torch.count_nonzero(new.decode_target(feat, c, codes, z[None])) == 0
        # and back: the no_neutral ablation started from a trained neutral-aware model computes what
        # that model does without the neutral (the flag's column folded into the bias)
        with torch.no_grad():
            new.expression_encoder.first.weight.normal_()   # as if trained: every column matters
        torch.manual_seed(2)
        narrow = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2))
        report = warm_start(narrow, new)
        assert report["narrowed"] == ["expression_encoder.first.weight"] and not report["widened"]
        torch.testing.assert_close(narrow.encode_expression(feat, c, ops),
                                   new.encode_expression(feat, c, ops), rtol=1e-5, atol=1e-5)
        assert not torch.allclose(narrow.encode_expression(feat, c, ops),
                                  new.encode_expression(feat, c, ops,
                                                        neutral=torch.zeros(feat.shape[0], NEUTRAL_CHANNEL_DIM)))
    same = NFSModel(NFSConfig.preset("tiny", decoder_width=16))   # same decoder kind, other widths
    report = warm_start(same, old)
    assert "decoder.0.weight" in report["fresh"] and "decoder.0.weight" not in report["copied"]
    assert torch.count_nonzero(same.decoder[-1].weight) > 0    # a same-kind decoder keeps its init


def test_warm_start_widens_the_encoders_without_changing_what_they_compute():
    from nets.model import NFSConfig, NFSModel
    from retarget.checkpoint import warm_start
    from retarget.prepare import neutral_channels

    torch.manual_seed(0)
    old = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2, neutral_channels=True))
    torch.manual_seed(1)
    new = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2, neutral_channels=True,
                                    enc_width=24))
    report = warm_start(new, old)
    assert not report["fresh"]
    assert {n.split(".")[0] for n in report["widened"]} == {"identity_encoder", "expression_encoder",
                                                            "skinning_encoder"}
    assert new.expression_encoder.first.weight.shape[0] == 24
    cfg = old.cfg
    rig, mesh, (feat, img, ops) = small_head(cfg)
    frame = mesh.canon.to_canonical(rig.evaluate(np.full(53, 0.3))).astype(np.float32)
    channels = torch.from_numpy(neutral_channels(frame, mesh.vertices, mesh.faces))
    with torch.no_grad():
        c = old.image_code(img)[0]
        for ch in (None, channels):
            torch.testing.assert_close(new.encode_expression(feat, c, ops, ch),
                                       old.encode_expression(feat, c, ops, ch), rtol=1e-5, atol=1e-6)
        a, b = old.encode_target(feat, c, ops), new.encode_target(feat, c, ops)
        torch.testing.assert_close(b.z_id, a.z_id, rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(b.z_skin, a.z_skin, rtol=1e-5, atol=1e-6)
    # the new channels train: one step of a loss on the code moves the weights that write them
    new.zero_grad()
    new.encode_expression(feat, c, ops).square().sum().backward()
    assert new.expression_encoder.first.weight.grad[16:].abs().sum() > 0


def test_warm_start_adds_skinning_descriptor_channels_the_decoder_then_learns_to_read(tmp_path):
    from nets.losses import rig_loss
    from nets.model import NFSConfig, NFSModel
    from retarget.checkpoint import warm_start

    with pytest.raises(ValueError, match="skin_descriptor needs decoder 'basis'"):
        NFSConfig.preset("tiny", skin_descriptor=4)
    torch.manual_seed(0)
    old = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2))
    with torch.no_grad():
        old.decoder[-1].weight.normal_(0, 0.1)        # as if trained: the rig is not zero
    new = NFSModel(NFSConfig.preset("tiny", decoder="basis", decoder_fourier=2, skin_descriptor=5))
    report = warm_start(new, old)
    assert sorted(report["widened"]) == ["decoder.0.weight", "skinning_encoder.last.bias",
                                         "skinning_encoder.last.weight"] and not report["fresh"]
    assert torch.count_nonzero(new.decoder[0].weight[:, -5:]) == 0
    assert torch.count_nonzero(new.skinning_encoder.last.weight[old.cfg.n_segments:]) == 0
    cfg = old.cfg
    rig, mesh, (feat, img, ops) = small_head(cfg)
    with torch.no_grad():
        c = old.image_code(img)[0]
        a, b = old.encode_target(feat, c, ops), new.encode_target(feat, c, ops)
        assert b.z_skin.shape == (feat.shape[0], cfg.n_segments + 5)
        torch.testing.assert_close(b.z_skin[:, :cfg.n_segments], a.z_skin)   # the segments kept
        torch.testing.assert_close(b.omega_skin, a.omega_skin)
        torch.testing.assert_close(b.basis, a.basis, rtol=1e-5, atol=1e-6)   # the same rig
        assert b.basis.abs().max() > 0
        assert torch.equal(b.z_skin[:, cfg.n_segments:], torch.full_like(b.z_skin[:, cfg.n_segments:], 0.5))
    # L_rig reaches the new channels: the decoder's new columns and the encoder's new rows
    basis = torch.from_numpy((rig.deltas * mesh.canon.scale).astype(np.float32))
    codes = new.encode_target(feat, c, ops, basis=False)
    rig_loss(new, feat, c, codes, basis).backward()
    assert new.decoder[0].weight.grad[:, -5:].abs().sum() > 0
    new.zero_grad()
    with torch.no_grad():
        new.decoder[0].weight[:, -5:].normal_()
    rig_loss(new, feat, c, new.encode_target(feat, c, ops, basis=False), basis).backward()
    assert new.skinning_encoder.last.weight.grad[cfg.n_segments:].abs().sum() > 0
    # a run of that design trains (L_nll on the segment channels only) and resumes from its file
    run_cfg = tiny_cfg(steps=2)
    run_cfg["model"] = {"preset": "tiny", "decoder": "basis", "skin_descriptor": 3}
    Trainer(run_cfg, tmp_path / "run", progress=False).run()
    log = (tmp_path / "run" / "train_log.csv").read_text().splitlines()
    header, last = log[0].split(","), log[-1].split(",")
    assert np.isfinite(float(last[header.index("L_nll")]))
    from retarget.checkpoint import model_from_checkpoint
    assert model_from_checkpoint(load_checkpoint(tmp_path / "run" / "model.pt")).cfg.skin_descriptor == 3


def test_warm_start_can_start_named_modules_fresh_where_they_fit():
    from nets.model import NFSConfig, NFSModel
    from retarget.checkpoint import warm_start
    torch.manual_seed(0)
    old = NFSModel(NFSConfig.preset("tiny"))
    torch.manual_seed(1)
    new = NFSModel(NFSConfig.preset("tiny"))
    report = warm_start(new, old, fresh=("decoder",))
    assert report["fresh"] and all(n.startswith("decoder.") for n in report["fresh"])
    assert not any(n.startswith("decoder.") for n in report["copied"])
    assert not torch.equal(new.decoder[0].weight, old.decoder[0].weight)
    assert torch.count_nonzero(new.decoder[-1].weight) == 0       # starts at doing nothing
    assert torch.equal(new.skinning_mlp[0].weight, old.skinning_mlp[0].weight)
    with pytest.raises(ValueError, match="no module dekoder"):
        warm_start(new, old, fresh=("dekoder",))


def test_init_partial_starts_a_run_from_another_design_and_needs_init(tmp_path):
    Trainer(tiny_cfg(), tmp_path / "a", progress=False).export(tmp_path / "tiny.pt")
    cfg = tiny_cfg(steps=2)
    cfg["model"] = {"preset": "tiny", "decoder": "basis", "neutral_channels": True}
    with pytest.raises(RetargetError, match="--init-partial"):
        Trainer(cfg, tmp_path / "b", init=tmp_path / "tiny.pt", progress=False)
    t = Trainer(cfg, tmp_path / "c", init=tmp_path / "tiny.pt", progress=False, init_partial=True)
    assert t.init_report["widened"] == ["expression_encoder.first.weight"]
    t.run()
    assert (tmp_path / "c" / "model.pt").is_file()
    res = subprocess.run([sys.executable, "-m", "retarget.cli", "train", "--config", str(TINY),
                          "--init-partial", "--out", str(tmp_path / "d")], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 2 and "--init-partial needs --init" in res.stderr
    res = subprocess.run([sys.executable, "-m", "retarget.cli", "train", "--config", str(TINY),
                          "--init", str(tmp_path / "tiny.pt"), "--init-fresh", "decoder",
                          "--out", str(tmp_path / "e")], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 2 and "--init-fresh needs --init-partial" in res.stderr


# each committed state (training/README.md) and the config its README resumes it under
#: training/NAME -> its config file, relative to the repository
COMMITTED_STATES = {"stage17": "configs/train/realistic_rig_heavier.yaml",
                    "stage18": "configs/train/realistic_rig_heavier.yaml",
                    "ablation_no_neutral": "configs/train/realistic_rig_heavier_no_neutral.yaml",
                    "ablation_no_neutral_19": "configs/train/realistic_rig_authored_no_neutral.yaml",
                    "ablation_no_neutral_20": "configs/train/realistic_rig_authored_no_neutral.yaml",
                    "stage19": "configs/train/realistic_rig_authored.yaml",
                    "stage20": "configs/train/realistic_rig_authored.yaml",
                    "stage23": "configs/train/realistic_rig_authored_decoder_neutral.yaml"}


def test_every_committed_state_is_listed():
    """A state added to training/ (a folder with last.pt) gets its resume test."""
    states = {p.parent.name for p in (ROOT / "training").glob("*/last.pt")}
    assert states == set(COMMITTED_STATES)


@pytest.mark.parametrize("name", sorted(COMMITTED_STATES))
def test_committed_resumable_state_resumes_under_its_config(tmp_path, name):
    """training/NAME (stage19: the bundled model's run) resumes under its config with the command
    its README gives: its model is the config's, its optimizer loads, and its step is that of the
    last row of its log, or a few steps past it for a run stopped by Ctrl-C."""
    import csv
    import shutil
    state_dir = ROOT / "training" / name
    run = tmp_path / "next"
    shutil.copytree(state_dir, run)
    cfg = load_config(ROOT / COMMITTED_STATES[name])
    cfg["train"]["seed"] = 1
    trainer = Trainer(cfg, run, progress=False)
    assert trainer.resume()
    with open(state_dir / "train_log.csv", newline="") as f:
        last = list(csv.DictReader(f))[-1]
    # a run stopped by Ctrl-C keeps the steps after its last log row (rows every log_every steps)
    assert 0 <= trainer.step - int(last["step"]) < cfg["train"]["log_every"] and trainer.step > 0
    # the bundled design's runs: L_rig, or (stage 21) only the blind encoder trains on a frozen rig
    assert trainer.cfg["loss"]["rig"] > 0 or trainer.cfg["train"]["trainable"] == ["blind_encoder"]


def test_a_blind_encoder_reads_sources_without_the_neutral_and_starts_as_the_old_reading():
    from nets.model import NFSConfig, NFSModel
    from retarget.checkpoint import warm_start
    from retarget.prepare import neutral_channels

    with pytest.raises(ValueError, match="blind_encoder needs neutral_channels"):
        NFSConfig.preset("tiny", blind_encoder=True)
    torch.manual_seed(0)
    old = NFSModel(NFSConfig.preset("tiny", decoder="basis", neutral_channels=True))
    with torch.no_grad():
        old.expression_encoder.first.weight.normal_()   # as if trained: the flag's column matters
    torch.manual_seed(1)
    new = NFSModel(NFSConfig.preset("tiny", decoder="basis", neutral_channels=True,
                                    blind_encoder=True))
    report = warm_start(new, old)
    assert report["narrowed"] == ["blind_encoder.first.weight"] and not report["fresh"]
    rig, mesh, (feat, img, ops) = small_head(old.cfg)
    frame = mesh.canon.to_canonical(rig.evaluate(np.full(53, 0.3))).astype(np.float32)
    channels = torch.from_numpy(neutral_channels(frame, mesh.vertices, mesh.faces))
    with torch.no_grad():
        c = old.image_code(img)[0]
        for ch in (None, channels):   # both readings start as the old model's
            torch.testing.assert_close(new.encode_expression(feat, c, ops, ch),
                                       old.encode_expression(feat, c, ops, ch), rtol=1e-5, atol=1e-5)
        # the blind encoder reads only sources without the neutral; the other encoder only those with it
        new.blind_encoder.last.bias += 1.0
        torch.testing.assert_close(new.encode_expression(feat, c, ops),
                                   old.encode_expression(feat, c, ops) + 1.0, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(new.encode_expression(feat, c, ops, channels),
                                   old.encode_expression(feat, c, ops, channels), rtol=1e-5, atol=1e-5)
        new.expression_encoder.last.bias += 1.0
        torch.testing.assert_close(new.encode_expression(feat, c, ops),
                                   old.encode_expression(feat, c, ops) + 1.0, rtol=1e-5, atol=1e-5)
    # started again from a model that has one, it is copied as it is
    again = NFSModel(new.cfg)
    assert not warm_start(again, new)["narrowed"]
    assert torch.equal(again.blind_encoder.last.bias, new.blind_encoder.last.bias)


def test_trainable_modules_train_and_every_other_weight_stays(tmp_path):
    cfg = tiny_cfg(steps=3)
    cfg["model"] = {"preset": "tiny", "decoder": "basis", "neutral_channels": True,
                    "blind_encoder": True}
    cfg["data"]["source_neutral_share"] = 0.0
    cfg["train"]["trainable"] = ["blind_encoder"]
    t = Trainer(cfg, tmp_path / "run", progress=False)
    before = {k: v.clone() for k, v in t.model.state_dict().items()}
    t.run()
    after = t.model.state_dict()
    moved = {k.split(".")[0] for k in before if not torch.equal(before[k], after[k])}
    assert moved == {"blind_encoder"}
    # resumes with the same frozen set and optimizer
    cfg["train"]["steps"] = 4
    resumed = Trainer(cfg, tmp_path / "run", progress=False)
    assert resumed.resume() and resumed.step == 3
    resumed.run()
    for bad in (["dekoder"], "blind_encoder", []):
        cfg["train"]["trainable"] = bad
        with pytest.raises(RetargetError, match="train.trainable must be null or a list"):
            Trainer(cfg, tmp_path / "bad", progress=False)

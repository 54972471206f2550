"""The trainer: ``retarget train --config configs/train/NAME.yaml``.

One step = one target neutral and S source expressions (``training_data.TargetPool.sample``): the
target's identity and skinning codes are computed once and every source is decoded on a random
subset of the target's faces. Losses are those of NFS eq. 2-9 (``nets.losses``), in canonical units.

Checkpoints (``last.pt`` in the run folder) hold plain types and tensors only and load with
``torch.load(weights_only=True)``; they are written atomically every ``ckpt_minutes`` and on Ctrl-C,
so ``--resume`` continues exactly (same samples, same parameters) after any interruption, SIGKILL
included, losing at most one interval. Several processes: ``torchrun --nproc_per_node N -m
retarget.cli train ...``; gradients are averaged across processes with all-reduce (gloo on the CPU,
nccl on CUDA), so every process keeps identical parameters.
"""
from __future__ import annotations

import csv
import math
import os
import signal
import time
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist

from nets import losses as L
from nets.model import NFSConfig, NFSModel

from .config import merge, read_yaml
from .checkpoint import (CHECKPOINT_FORMAT, load_checkpoint, model_from_checkpoint, put_code_map,
                         save_checkpoint, warm_start)
from .errors import RetargetError
from .metrics import CM_TO_MM, segment_mse_mm2
from .prepare import IMAGE_CHANNELS, vertex_features
from .render import render_frontal
from .prefetch import PrefetchPool
from .training_data import Group, make_pool, validation_entries

DEFAULTS = {
    "model": {"preset": "cpu"},
    "data": {
        "n_identities": 1000, "pool_size": 32, "pool_refresh": 25,
        "tessellations": [{"n_vertices": 2500, "kind": "adaptive", "region": "full"}],
        "pairs": {"self": 0.5, "cross_topology": 0.2, "cross_identity": 0.3},
        "weights": "mixed", "sources_per_target": 4, "decode_faces": 1000,
        "augment": {"rotate_deg": 3.0, "scale": 0.05, "translate": 0.5},
        "val_identities": 4, "val_expressions": 4,
        # heads L_rig draws its rig on each step: the group's target and rig_targets - 1 more of
        # the pool (TargetPool's groups; those drawn from a user rig, data.rig, keep one)
        "rig_targets": 1,
        "rig": None, "keep_vertices": None, "rig_mix": 0.5, "rig_strict": False,
        "source_neutral_share": 0.5,  # sources given their neutral (neutral-aware models only)
        # shares of the two rig sources among the pool's identities (training_data.TargetPool)
        "sources": {"procedural": 1.0, "makehuman": 0.0},
        "makehuman": {
            "tessellations": [{"n_vertices": 2500, "kind": "decimated", "crop": "head_neck"}],
            "expressions": {"arkit": 1.0, "units": 0.0, "units_full": 0.0}, "style": True,
            "stylised_share": 0.15, "partial_macro_share": 0.0,
        },
    },
    "loss": {"lambda_v": 10.0, "lambda_n": 1.0, "lambda_g": 1.0, "id": 1.0, "exp": 1.0,
             "bp": 1.0, "br": 1.0, "nll": 1.0, "rig": 0.0, "free_dims_dropout": 0.0,
             # L_rig relative to each shape's size (nets.losses.rig_loss's τ; 0 = plain)
             "rig_relative": 0.0,
             # L_corr: skinning descriptor channels 0-2 as template positions (realistic heads)
             "corr": 0.0,
             # L_solve: inverse rigging's weights on the decoder's baked rig (nets.losses.solve_loss)
             # for solve_frames frames of the eval's mixed weights a head, ridge solve_ridge
             "solve": 0.0, "solve_frames": 16, "solve_ridge": 0.01},
    "optim": {"lr": 1e-3, "weight_decay": 1e-4, "warmup_steps": 100, "grad_clip": 1.0},
    # the code map fitted into model.pt at export (retarget.code_map; basis decoder): this many
    # MakeHuman and as many procedural training identities from seed ``seed``; 0 = none. gated:
    # the map of the MakeHuman heads, given to each head by a gate on its identity code;
    # features d > 0: the map of each head linear in d principal components of its identity code
    "code_map": {"identities": 0, "seed": 0, "ridge": 0.01, "gated": False, "features": 0},
    "train": {"steps": 1000, "max_minutes": 0, "seed": 0, "log_every": 10, "val_every": 200,
              "ckpt_minutes": 5.0,
              # processes preparing the samples of the next steps (retarget.prefetch); 0 = in the
              # training process. The samples are the same either way.
              "data_workers": 0,
              # the top-level modules that train (e.g. [blind_encoder]); null = all. The others
              # keep the weights they start with (--init), and the optimizer holds only these.
              "trainable": None},
}


# ------------------------------------------------------------------------------------- config
def load_config(path, _seen=()) -> dict:
    """Read a training YAML and fill in defaults. RetargetError names the file and the bad key.

    A config may start from another one, ``base: default.yaml`` (relative to its own folder), and
    change only what differs (the ablations do). ``model`` keys add to the base's model keys.
    """
    path = Path(path)
    raw = read_yaml(path, "training config")
    base = raw.pop("base", None)
    if base is not None:
        base_path = path.parent / str(base)
        if base_path.resolve() in _seen:
            raise RetargetError(f"{path}: base {base!r} includes itself")
        defaults = load_config(base_path, _seen + (path.resolve(),))
    else:
        defaults = DEFAULTS
    if isinstance(raw.get("model"), dict):
        raw["model"] = {**defaults["model"], **raw["model"]}
    cfg = merge(defaults, raw, str(path), replace=("model",))
    decoder = model_cfg(cfg, str(path)).decoder  # validates the model section
    check_values(cfg, str(path))
    if not isinstance(cfg["code_map"]["gated"], bool):
        raise RetargetError(f"{path}: code_map.gated must be true or false, got "
                            f"{str(cfg['code_map']['gated'])[:40]!r}")
    if cfg["code_map"]["identities"] and decoder != "basis":
        raise RetargetError(f"{path}: code_map needs the basis decoder (model.decoder: basis); "
                            "set code_map.identities to 0")
    return cfg


#: (section, key) -> (kind, lowest, highest, lowest allowed?): the numbers of a training config.
VALUE_RULES = {
    ("train", "steps"): (int, 1, None, True), ("train", "seed"): (int, 0, None, True),
    ("train", "log_every"): (int, 1, None, True), ("train", "val_every"): (int, 1, None, True),
    ("train", "max_minutes"): (float, 0.0, None, True), ("train", "ckpt_minutes"): (float, 0.0, None, True),
    ("train", "data_workers"): (int, 0, 256, True),
    ("optim", "lr"): (float, 0.0, None, False), ("optim", "weight_decay"): (float, 0.0, None, True),
    ("optim", "warmup_steps"): (int, 0, None, True), ("optim", "grad_clip"): (float, 0.0, None, False),
    ("data", "n_identities"): (int, 1, None, True), ("data", "pool_size"): (int, 1, None, True),
    ("data", "pool_refresh"): (int, 1, None, True), ("data", "sources_per_target"): (int, 1, None, True),
    ("data", "decode_faces"): (int, 0, None, True), ("data", "rig_mix"): (float, 0.0, 1.0, True),
    ("data", "val_identities"): (int, 1, None, True), ("data", "val_expressions"): (int, 1, None, True),
    ("data", "rig_targets"): (int, 1, 64, True),
    **{("loss", k): (float, 0.0, None, True) for k in DEFAULTS["loss"]},
    ("code_map", "identities"): (int, 0, 10000, True), ("code_map", "seed"): (int, 0, None, True),
    ("code_map", "ridge"): (float, 0.0, None, False), ("code_map", "features"): (int, 0, 10000, True),
}


def check_values(cfg: dict, where: str = "config") -> None:
    """RetargetError naming ``where`` and the key for a number of the config (:data:`VALUE_RULES`)
    of the wrong type, not finite or out of range: 0 or negative steps, a negative learning rate..."""
    for (section, key), (kind, lo, hi, lo_ok) in VALUE_RULES.items():
        value = cfg[section][key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        ok = (number and (kind is float or isinstance(value, int)) and math.isfinite(value)
              and (value >= lo if lo_ok else value > lo) and (hi is None or value <= hi))
        if not ok:
            span = f"{'>=' if lo_ok else '>'} {lo}" + (f" and <= {hi}" if hi is not None else "")
            raise RetargetError(f"{where}: {section}.{key} must be {'an integer' if kind is int else 'a number'} "
                                f"{span}, got {str(value)[:40]!r}")


#: The files of a run folder; another run's are never overwritten without --resume.
RUN_FILES = ("last.pt", "model.pt", "train_log.csv")


def check_run_folder(out, resume: bool) -> None:
    """RetargetError naming the file unless ``out`` can take this run: it must be a folder (or not
    exist yet), and hold no file of another run (:data:`RUN_FILES`) unless ``resume``, which then
    needs that run's ``last.pt``."""
    out = Path(out)
    if str(out) == "-":
        raise RetargetError("-: a training run is written to a folder; give --out FOLDER")
    if out.exists() and not out.is_dir():
        raise RetargetError(f"{out}: exists and is not a folder (--out is the run folder)")
    held = [out / name for name in RUN_FILES if (out / name).exists()]
    if held and not resume:
        raise RetargetError(f"{held[0]}: another run's output is in {out}; pass --resume to continue "
                            "that run or choose another --out")
    if held and resume and not (out / "last.pt").is_file():
        raise RetargetError(f"{held[0]}: another run's output, without the last.pt that --resume "
                            "continues from; choose another --out")


def model_cfg(cfg: dict, where: str = "config") -> NFSConfig:
    """The NFSConfig of a training config: ``model: {preset: NAME, <field>: value, ...}``."""
    m = dict(cfg["model"])
    try:
        return NFSConfig.preset(m.pop("preset", "cpu"), **m)
    except (ValueError, TypeError) as e:
        raise RetargetError(f"{where}: model: {e}") from None


def trainable_parameters(model: NFSModel, trainable, where: str = "config") -> list:
    """The parameters that train (``train.trainable``: top-level module names, or None for all);
    every other parameter is frozen (``requires_grad`` False). RetargetError naming ``where`` for
    a name that is not one of the model's modules."""
    if trainable is None:
        return list(model.parameters())
    modules = [name for name, _ in model.named_children()]
    if (not isinstance(trainable, list) or not trainable
            or not all(isinstance(n, str) and n in modules for n in trainable)):
        raise RetargetError(f"{where}: train.trainable must be null or a list of the model's "
                            f"modules ({', '.join(modules)}), got {str(trainable)[:80]!r}")
    params = []
    for name, module in model.named_children():
        for p in module.parameters():
            p.requires_grad_(name in trainable)
            if name in trainable:
                params.append(p)
    return params


# ------------------------------------------------------------------------------------- devices
def pick_device() -> torch.device:
    """CUDA when present (the local rank's GPU under torchrun), else the CPU."""
    if torch.cuda.is_available():
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    return torch.device("cpu")


def init_distributed(device: torch.device) -> tuple[int, int]:
    """(rank, world size); joins the process group when launched by torchrun (WORLD_SIZE > 1)."""
    world = int(os.environ.get("WORLD_SIZE", 1))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


def shutdown_distributed() -> None:
    """Leave the process group, if one was joined: a barrier first, so that no rank tears down its
    connections while another is still communicating (gloo aborts the process when it does)."""
    if dist.is_available() and dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()


def average_gradients(model: torch.nn.Module, world: int) -> None:
    """All-reduce (mean) every gradient across processes in one flat buffer."""
    if world == 1:
        return
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    flat = torch.cat([g.reshape(-1) for g in grads])
    dist.all_reduce(flat)
    flat /= world
    offset = 0
    for g in grads:
        g.copy_(flat[offset:offset + g.numel()].view_as(g))
        offset += g.numel()


# ------------------------------------------------------------------------------------- losses
def face_subset(faces: np.ndarray, n_faces: int, rng: np.random.Generator):
    """Random faces of the target and the vertices they use.

    Returns (rows (n,) int64 vertex indices, sub_faces (m,3) int64 re-indexed into rows).
    """
    if n_faces <= 0 or n_faces >= len(faces):
        chosen = faces
    else:
        chosen = faces[rng.choice(len(faces), n_faces, replace=False)]
    rows, inverse = np.unique(chosen, return_inverse=True)
    return rows, inverse.reshape(-1, 3)


def free_dims_dropout(z_ge: torch.Tensor, n_facs: int, p: float, rng: np.random.Generator):
    """z_GE (S, D) for L_dec with, for each source with probability ``p``, the dims past the FACS
    weights set to 0: the decoder then also learns from codes shaped like z_GE = [w, 0], what
    driving from FACS weights (``Retargeter.animate``, the baked rig) feeds it. p = 0: unchanged."""
    if p <= 0:
        return z_ge
    drop = torch.from_numpy(rng.random(z_ge.shape[0]) < p).to(z_ge.device)
    keep = torch.ones_like(z_ge)
    keep[:, n_facs:] = (~drop).to(z_ge.dtype)[:, None]
    return z_ge * keep


#: The encoder and segmentation terms added to L_dec, in this order, with their config weights.
LOSS_WEIGHTS = (("L_ID", "id"), ("L_Exp", "exp"), ("L_BP", "bp"), ("L_BR", "br"), ("L_nll", "nll"),
                ("L_rig", "rig"), ("L_corr", "corr"), ("L_solve", "solve"))

#: Shapes per step that L_rig decodes with the MLP decoder (one decoder pass each); the basis
#: decoder's rig holds all 53 at no extra cost.
RIG_SHAPES_MLP = 8


def rig_shapes(model: NFSModel, present: np.ndarray | None, rng: np.random.Generator) -> torch.Tensor:
    """The FACS shape indices (K,) int64 that L_rig decodes this step: the target rig's shapes
    (``Entry.present``; all 53 when None), all of them for the basis decoder, ``RIG_SHAPES_MLP``
    drawn at random for the MLP decoder."""
    have = np.arange(model.cfg.n_facs) if present is None else np.flatnonzero(present)
    if model.cfg.decoder != "basis" and len(have) > RIG_SHAPES_MLP:
        have = np.sort(rng.choice(have, RIG_SHAPES_MLP, replace=False))
    return torch.from_numpy(have.astype(np.int64))


def extra_rig_loss(model: NFSModel, entry, loss_cfg: dict, n_faces: int,
                   rng: np.random.Generator, device) -> torch.Tensor:
    """L_rig (scalar, canonical units²) on one more head of the pool (``Group.rig_targets``):
    its own target codes, decoded on ``n_faces`` random faces like the group's target."""
    feat, img, ops = entry.mesh.torch_inputs(device)
    c = model.image_code(img)[0]
    codes = model.encode_target(feat, c, ops)
    rows = torch.from_numpy(face_subset(entry.mesh.faces, n_faces, rng)[0]).to(device)
    shapes = rig_shapes(model, entry.present, rng).to(device)
    return L.rig_loss(model, feat, c, codes, torch.from_numpy(entry.basis).to(device), rows, shapes,
                      loss_cfg["rig_relative"])


def solve_term(model: NFSModel, feat, c, codes, basis: torch.Tensor, present, rows,
               loss_cfg: dict, rng: np.random.Generator) -> torch.Tensor:
    """L_solve (``nets.losses.solve_loss``) on ``loss_cfg["solve_frames"]`` frames of the eval's
    mixed weights (``data_synth.sampling.sample_weights``), the shapes the rig lacks (``present``
    False) at 0."""
    from data_synth.sampling import sample_weights

    w = sample_weights(rng, int(loss_cfg["solve_frames"]), mode="mixed")
    if present is not None:
        w[:, ~np.asarray(present, bool)] = 0.0
    w = torch.from_numpy(w.astype(np.float32)).to(basis.device)
    return L.solve_loss(model, feat, c, codes, basis, w, rows, float(loss_cfg["solve_ridge"]))


def group_losses(model: NFSModel, group: Group, loss_cfg: dict, n_faces: int,
                 rng: np.random.Generator, device) -> dict[str, torch.Tensor]:
    """All NFS losses (eq. 2-9) of one training group; returns named scalars and ``total``.

    On a user rig (``training_data.RigPool``) L_ID is left out when the target has no identity
    coefficients, L_nll when it has no segment labels, and L_Exp / L_BR supervise only the shapes
    the rig has (``Entry.present``). L_corr needs a model with skinning descriptor channels and a
    realistic head target (``Entry.template``)."""
    tgt = group.target
    t_feat, t_img, t_ops = tgt.mesh.torch_inputs(device)
    images = torch.from_numpy(np.stack([tgt.mesh.image] + [s.image for s in group.sources]))
    codes_img = model.image_code(images.to(device))
    c_t = codes_img[0]
    codes = model.encode_target(t_feat, c_t, t_ops)
    z_ge = torch.stack([
        model.encode_expression(torch.from_numpy(s.feat).to(device), codes_img[i + 1],
                                s.entry.mesh.torch_ops(device),
                                None if s.neutral is None else torch.from_numpy(s.neutral).to(device))
        for i, s in enumerate(group.sources)])
    weights = torch.from_numpy(np.stack([s.weights for s in group.sources])).to(device)
    z_exp, w_exp, z_br = z_ge, weights, z_ge
    if tgt.present is not None and not tgt.present.all():
        # a user rig lacking shapes: L_Exp leaves their z_GE dims free and L_BR decodes them as
        # zero (L_BP ignores them already: their basis rows are zero)
        present = torch.from_numpy(tgt.present).to(device)                           # (53,)
        keep = torch.cat([present, present.new_ones(z_ge.shape[1] - len(present))])  # (128,)
        z_exp, w_exp, z_br = z_ge[:, keep], weights[:, present], z_ge * keep

    rows_np, sub_faces_np = face_subset(tgt.mesh.faces, n_faces, rng)
    rows = torch.from_numpy(rows_np).to(device)
    sub_faces = torch.from_numpy(sub_faces_np).to(device)
    rest = t_feat[rows, :3]
    dv = model.decode_target(t_feat, c_t, codes, free_dims_dropout(z_ge, model.cfg.n_facs,
                                                                    loss_cfg["free_dims_dropout"], rng),
                             rows)                                                 # (S, n, 3)
    gt = torch.from_numpy(group.gt_dv).to(device)[:, rows]
    out = L.decoder_loss(rest + dv, rest + gt, rest, sub_faces, loss_cfg["lambda_v"],
                         loss_cfg["lambda_n"], loss_cfg["lambda_g"])
    if tgt.rig.identity is not None:  # a user rig has no procedural identity coefficients
        identity_gt = torch.from_numpy(tgt.rig.identity.astype(np.float32)).to(device)
        out["L_ID"] = L.identity_loss(codes.z_id, identity_gt)
    out["L_Exp"] = L.expression_loss(z_exp, w_exp)
    out["L_BP"] = torch.stack([
        L.blendshape_projection_loss(g, w, torch.from_numpy(s.entry.basis).to(device))
        for g, w, s in zip(z_ge, weights, group.sources)]).mean()
    basis_t = torch.from_numpy(tgt.basis).to(device)
    out["L_BR"] = L.blendshape_reconstruction_loss(model, t_feat, c_t, codes, z_br, basis_t, rows)
    if loss_cfg["rig"] > 0:
        shapes = rig_shapes(model, tgt.present, rng).to(device)
        rig = [L.rig_loss(model, t_feat, c_t, codes, basis_t, rows, shapes, loss_cfg["rig_relative"])]
        rig += [extra_rig_loss(model, e, loss_cfg, n_faces, rng, device) for e in group.rig_targets]
        out["L_rig"] = torch.stack(rig).mean()   # the mean over the step's heads
    if loss_cfg["solve"] > 0:
        out["L_solve"] = solve_term(model, t_feat, c_t, codes, basis_t, tgt.present, rows, loss_cfg, rng)
    n_seg = model.cfg.n_segments
    if loss_cfg["corr"] > 0 and model.cfg.skin_descriptor >= 3 and tgt.template is not None:
        out["L_corr"] = L.correspondence_loss(codes.z_skin[:, n_seg:n_seg + 3],
                                              torch.from_numpy(tgt.template).to(device))
    if codes.z_skin is not None and tgt.rig.segments is not None:
        labels = torch.from_numpy(tgt.rig.segments).to(device)
        out["L_nll"] = L.segmentation_nll(codes.z_skin[:, :n_seg], labels)
    total = out["L_dec"]
    for term, weight in LOSS_WEIGHTS:
        if term in out:
            total = total + loss_cfg[weight] * out[term]
    out["total"] = total
    return out


@torch.no_grad()
def validate(model: NFSModel, val_set, device) -> dict[str, float]:
    """Self-retargeting on held-out identities: MSE and segment-averaged MSE in mm², weight MAE."""
    model.eval()
    mse, seg, mae = [], [], []
    for entry, weights in val_set:
        t_feat, t_img, t_ops = entry.mesh.torch_inputs(device)
        c_t = model.image_code(t_img)[0]
        codes = model.encode_target(t_feat, c_t, t_ops)
        for w in weights:
            frame = entry.mesh.canon.to_canonical(entry.rig.evaluate(w)).astype(np.float32)
            feat = torch.from_numpy(vertex_features(frame, entry.mesh.faces)).to(device)
            img = render_frontal(frame, entry.mesh.faces, model.cfg.image_size,
                                 channels=IMAGE_CHANNELS[model.cfg.image_channels],
                                 fit=entry.mesh.canon.render_fit)
            c_s = model.image_code(torch.from_numpy(img)[None].to(device))[0]
            z_ge = model.encode_expression(feat, c_s, t_ops)
            dv = model.decode_target(t_feat, c_t, codes, z_ge).cpu().numpy()
            pred_cm = dv / entry.mesh.canon.scale
            gt_cm = np.einsum("k,kvc->vc", w, entry.rig.deltas)
            s, _ = segment_mse_mm2(pred_cm, gt_cm, entry.rig.segments, model.cfg.n_segments)
            mse.append(float((((pred_cm - gt_cm) * CM_TO_MM) ** 2).sum(-1).mean()))
            seg.append(s)
            mae.append(float(np.abs(z_ge[:53].cpu().numpy() - w).mean()))
    model.train()
    return {"val_mse_mm2": float(np.mean(mse)), "val_seg_mse_mm2": float(np.mean(seg)),
            "val_weight_mae": float(np.mean(mae))}


def learning_rate(progress: float, step: int, optim_cfg: dict) -> float:
    """Linear warm-up over ``warmup_steps``, then cosine decay to 5 % of the base rate as
    ``progress`` (fraction of the run done, 0..1) goes to 1."""
    base, warm = optim_cfg["lr"], max(1, optim_cfg["warmup_steps"])
    if step < warm:
        return base * (step + 1) / warm
    t = min(1.0, max(0.0, progress))
    return base * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * t)))


LOG_COLUMNS = ("step", "elapsed_s", "lr", "samples_per_s", "total", "L_dec", "L_v", "L_n", "L_g",
               "L_ID", "L_Exp", "L_BP", "L_BR", "L_nll", "L_rig", "L_corr", "L_solve", "val_mse_mm2",
               "val_seg_mse_mm2",
               "val_weight_mae")


class Trainer:
    """Runs one training config into ``out_dir`` (``last.pt``, ``model.pt``, ``train_log.csv``)."""

    def __init__(self, cfg: dict, out_dir, config_path: str = "", init=None, progress=True,
                 init_partial: bool = False, init_fresh: tuple[str, ...] = ()):
        self.cfg, self.out = cfg, Path(out_dir)
        check_values(cfg, config_path or "config")
        self.device = pick_device()
        self.rank, self.world = init_distributed(self.device)
        self.model_cfg = model_cfg(cfg)
        seed = cfg["train"]["seed"]
        torch.manual_seed(seed)
        self.model = NFSModel(self.model_cfg).to(self.device)
        self.init_report: dict[str, list[str]] | None = None
        if init is not None:
            initial = model_from_checkpoint(load_checkpoint(init), init)
            if init_partial:
                try:
                    self.init_report = warm_start(self.model, initial, tuple(init_fresh))
                except ValueError as e:
                    raise RetargetError(f"--init-fresh: {e}") from None
            elif initial.cfg != self.model_cfg:
                raise RetargetError(f"{init}: the checkpoint's model does not match the config's "
                                    f"(model: {cfg['model']}); leave --config out to fine-tune "
                                    f"with the checkpoint's own model, or give --init-partial to "
                                    f"start a new design from the weights that fit")
            else:
                self.model.load_state_dict(initial.state_dict())
        if self.world > 1:
            for p in self.model.parameters():
                dist.broadcast(p.data, 0)
        self.opt = torch.optim.AdamW(trainable_parameters(self.model, cfg["train"]["trainable"],
                                                          config_path or "config"),
                                     lr=cfg["optim"]["lr"],
                                     weight_decay=cfg["optim"]["weight_decay"])
        workers = cfg["train"]["data_workers"]
        self.pool = (PrefetchPool(cfg["data"], self.model_cfg, seed, workers, self.rank) if workers
                     else make_pool(cfg["data"], self.model_cfg, seed))
        self.step, self.elapsed = 0, 0.0
        self.config_path = config_path
        self.progress = progress and self.rank == 0
        self._stop = False
        self._log_columns: tuple[str, ...] | None = None   # train_log.csv's, fixed at its first row

    # ---- state
    def state(self) -> dict:
        return {"format": CHECKPOINT_FORMAT, "model_config": self.model_cfg.to_dict(),
                "train_config": self.cfg, "model": self.model.state_dict(),
                "optimizer": self.opt.state_dict(), "step": self.step, "elapsed_s": self.elapsed,
                "torch_rng": torch.get_rng_state()}

    def resume(self) -> bool:
        """Continue from ``last.pt`` if present. Returns whether a checkpoint was loaded."""
        path = self.out / "last.pt"
        if not path.exists():
            return False
        state = load_checkpoint(path)
        saved = model_from_checkpoint(state, path)
        if saved.cfg != self.model_cfg:
            raise RetargetError(f"{path}: the run's model differs from the config's (model: "
                                f"{self.cfg['model']}); resume with the run's own config")
        self.model.load_state_dict(saved.state_dict())
        try:
            self.opt.load_state_dict(state["optimizer"])
        except (KeyError, ValueError, TypeError, RuntimeError) as e:
            raise RetargetError(f"{path}: the optimizer state does not match the model "
                                f"({str(e).splitlines()[0][:200]})") from None
        if not isinstance(state.get("torch_rng"), torch.Tensor) or state["torch_rng"].dtype != torch.uint8:
            raise RetargetError(f"{path}: the checkpoint's torch_rng is not a random-generator state")
        self.step, self.elapsed = int(state["step"]), float(state["elapsed_s"])
        torch.set_rng_state(state["torch_rng"])
        return True

    def save(self) -> None:
        if self.rank == 0:
            save_checkpoint(self.out / "last.pt", self.state())

    def export(self, path: Path) -> None:
        """The inference checkpoint: config + model weights only (small), and the code map when
        the config asks for one (``code_map.identities`` > 0, fitted now: ``fit_code_map``)."""
        if self.rank == 0:
            state = {"format": CHECKPOINT_FORMAT, "model_config": self.model_cfg.to_dict(),
                     "train_config": self.cfg, "model": self.model.state_dict(), "step": self.step}
            if self.cfg["code_map"]["identities"]:
                put_code_map(state, *self.fit_code_map())
            save_checkpoint(path, state)

    def fit_code_map(self) -> tuple[np.ndarray, np.ndarray | None, tuple | None, np.ndarray]:
        """The code map (code_dim, 53) float32 of the model as it is now, its gate (or None), its
        per-head part (or None) and its error moments, on the config's ``code_map`` training identities
        (``retarget.code_map.fit_code_map``); the model's mode is kept."""
        from .api import Retargeter
        from .code_map import fit_code_map

        c, was_training = self.cfg["code_map"], self.model.training
        try:
            return fit_code_map(Retargeter(self.model, self.device), c["identities"], c["seed"],
                                c["ridge"], c["gated"], c["features"])
        finally:
            self.model.train(was_training)

    # ---- loop
    def _log(self, row: dict) -> None:
        if self.rank != 0:
            return
        path = self.out / "train_log.csv"
        new = not path.exists() or path.stat().st_size == 0
        if self._log_columns is None:  # a resumed run keeps its log's columns (an older log may
            self._log_columns = LOG_COLUMNS  # have no L_rig): read once per run
            if not new:
                with open(path, newline="") as f:
                    self._log_columns = tuple(next(csv.reader(f), None) or LOG_COLUMNS)
        with open(path, "a", newline="") as f:
            w = csv.DictWriter(f, self._log_columns, extrasaction="ignore")
            if new:
                w.writeheader()
            w.writerow(row)

    def run(self, stop_at: int | None = None) -> dict:
        """Train until ``steps`` or ``max_minutes`` (or, as if interrupted, ``stop_at``); save
        ``last.pt`` and ``model.pt``; return the last validation metrics."""
        tcfg, dcfg = self.cfg["train"], self.cfg["data"]
        total_steps = tcfg["steps"]
        self.out.mkdir(parents=True, exist_ok=True)
        val_set = validation_entries(dcfg, self.model_cfg, tcfg["seed"]) if self.rank == 0 else []
        previous = signal.signal(signal.SIGINT, self._request_stop)
        metrics: dict = {}
        last_ckpt = time.monotonic()
        from tqdm import tqdm
        bar = tqdm(total=total_steps, initial=self.step, disable=not self.progress,
                   desc="train", dynamic_ncols=True)
        running: dict[str, float] = {}
        try:
            while self.step < min(total_steps, stop_at or total_steps):
                self._agree_on_clock_and_stop()
                if self._stop:
                    break
                if tcfg["max_minutes"] and self.elapsed >= 60 * tcfg["max_minutes"]:
                    break
                t0 = time.monotonic()
                lr = learning_rate(self.run_fraction(), self.step, self.cfg["optim"])
                for g in self.opt.param_groups:
                    g["lr"] = lr
                group = self.pool.sample(self.step, self.rank)
                rng = np.random.default_rng([tcfg["seed"], self.step, self.rank, 1])
                losses = group_losses(self.model, group, self.cfg["loss"], dcfg["decode_faces"],
                                      rng, self.device)
                self.opt.zero_grad(set_to_none=True)
                losses["total"].backward()
                average_gradients(self.model, self.world)
                torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.cfg["optim"]["grad_clip"])
                self.opt.step()
                self.step += 1
                dt = time.monotonic() - t0
                self.elapsed += dt
                for k, v in losses.items():
                    v = float(v.detach())
                    running[k] = 0.9 * running.get(k, v) + 0.1 * v
                bar.update(1)
                bar.set_postfix(loss=f"{running['total']:.4f}", Lv=f"{running['L_v']:.4f}")
                row = None
                if self.step % tcfg["log_every"] == 0:
                    row = {"step": self.step, "elapsed_s": round(self.elapsed, 1), "lr": f"{lr:.3g}",
                           "samples_per_s": round(len(group.sources) * self.world / dt, 2),
                           **{k: f"{v:.5g}" for k, v in running.items()}}
                if self.rank == 0 and (self.step % tcfg["val_every"] == 0 or self.step == total_steps):
                    metrics = validate(self.model, val_set, self.device)
                    row = {**(row or {"step": self.step, "elapsed_s": round(self.elapsed, 1)}),
                           **{k: f"{v:.4f}" for k, v in metrics.items()}}
                    bar.write(f"step {self.step}: " + ", ".join(f"{k} {v:.4f}" for k, v in metrics.items()))
                if row:
                    self._log(row)
                if time.monotonic() - last_ckpt > 60 * tcfg["ckpt_minutes"]:
                    self.save()
                    last_ckpt = time.monotonic()
        finally:
            bar.close()
            signal.signal(signal.SIGINT, previous)
            if isinstance(self.pool, PrefetchPool):
                self.pool.close()
        self.save()
        self.export(self.out / "model.pt")
        return metrics

    def run_fraction(self) -> float:
        """Fraction of the run done: by steps, or by training time when ``max_minutes`` is set and
        comes first (then the schedule follows the clock, and a resumed run continues it from the
        saved elapsed time rather than bit for bit)."""
        tcfg = self.cfg["train"]
        done = self.step / max(1, tcfg["steps"])
        if tcfg["max_minutes"]:
            done = max(done, self.elapsed / (60.0 * tcfg["max_minutes"]))
        return done

    def _agree_on_clock_and_stop(self) -> None:
        """Under torchrun every rank takes the slowest rank's training time and stops when any rank
        was asked to: the learning-rate schedule (which may follow the clock), the time budget and
        Ctrl-C then act on all ranks at the same step, and their parameters stay identical."""
        if self.world == 1:
            return
        flags = torch.tensor([self.elapsed, float(self._stop)], dtype=torch.float64,
                             device=self.device)
        dist.all_reduce(flags, op=dist.ReduceOp.MAX)
        self.elapsed, self._stop = float(flags[0]), bool(flags[1])

    def _request_stop(self, signum, frame):
        """Ctrl-C: finish the current step, save, exit cleanly."""
        self._stop = True

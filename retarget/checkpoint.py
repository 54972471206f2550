"""Checkpoint files: plain types and tensors only, loaded with ``torch.load(weights_only=True)``
(a tampered file carrying pickled objects is refused), written atomically.

A checkpoint is data, never code, and its contents are not trusted: :func:`load_checkpoint` checks
every field the project reads (the model config against ``NFSConfig``'s types and bounds, the
weights against the shapes that config gives, before any memory is allocated for them), so an
absurd or mistyped value is one error line naming the file, never a hang or a traceback.
"""
from __future__ import annotations

import math
import pickle
from pathlib import Path

import numpy as np
import torch

from data_synth.facs import N_FACS
from nets.model import NEUTRAL_CHANNEL_DIM, NFSConfig, NFSModel

from .code_map import check_code_map, check_gate, check_map_error, check_per_head
from .errors import RetargetError
from .io import atomic_output, regular_file
from .prepare import IMAGE_CHANNELS

CHECKPOINT_FORMAT = "retarget-checkpoint/1"


def save_checkpoint(path: Path, state: dict) -> None:
    """Write atomically (``retarget.io.atomic_output``: temporary file in the same folder, then
    rename; a killed writer's leftovers are removed by the next write there)."""
    with atomic_output(path) as tmp:
        torch.save(state, tmp)


def load_checkpoint(path) -> dict:
    """Load a checkpoint with ``weights_only=True`` and check its fields (:func:`check_state`);
    RetargetError names the file and the problem."""
    path = regular_file(path, "checkpoint", missing="checkpoint not found")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:  # torch's message advises turning the protection off: not shown
        if "unsupported global" in str(e).lower():  # a reference to a class or function
            raise RetargetError(f"{path}: holds pickled code (Python objects, not only tensors and "
                                "plain values) and was refused: a checkpoint is data, never code") from None
        raise RetargetError(f"{path}: not a loadable checkpoint (corrupt, or not a checkpoint "
                            "file)") from None
    except Exception as e:  # torch raises many types for a corrupt file
        raise RetargetError(f"{path}: not a loadable checkpoint ({type(e).__name__}: "
                            f"{(str(e).splitlines() or [''])[0][:200]})") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise RetargetError(f"{path}: not a retarget checkpoint (format "
                            f"{str(state.get('format'))[:60] if isinstance(state, dict) else type(state).__name__!r})")
    check_state(state, path)
    return state


def checkpoint_config(state: dict, path="checkpoint") -> NFSConfig:
    """The NFSConfig of a checkpoint's ``model_config``, checked (types and bounds, see
    ``NFSConfig``; renders with a channel count the pipeline makes; 53 FACS weights)."""
    raw = state.get("model_config")
    if not isinstance(raw, dict):
        raise RetargetError(f"{path}: the checkpoint's model_config is a {type(raw).__name__}, not a "
                            "mapping of model settings")
    try:
        cfg = NFSConfig.from_dict(raw)
    except (TypeError, ValueError) as e:
        raise RetargetError(f"{path}: bad model_config in the checkpoint ({str(e)[:200]})") from None
    if cfg.image_channels not in IMAGE_CHANNELS or cfg.n_facs != N_FACS:
        raise RetargetError(f"{path}: bad model_config in the checkpoint (image_channels "
                            f"{cfg.image_channels}, n_facs {cfg.n_facs}; this version renders "
                            f"{sorted(IMAGE_CHANNELS)} channels and drives {N_FACS} FACS weights)")
    return cfg


def check_state(state: dict, path="checkpoint") -> None:
    """RetargetError naming ``path`` unless the fields the project reads are what it writes: a
    valid model config, ``model`` a mapping of names to tensors, ``step`` an integer >= 0,
    ``elapsed_s`` a finite number >= 0, ``optimizer`` / ``train_config`` mappings (when present)."""
    cfg = checkpoint_config(state, path)
    model = state.get("model")
    if not isinstance(model, dict) or not all(isinstance(k, str) and isinstance(v, torch.Tensor)
                                              for k, v in model.items()):
        raise RetargetError(f"{path}: the checkpoint's model is not a mapping of names to tensors")
    step, elapsed = state.get("step", 0), state.get("elapsed_s", 0.0)
    if not isinstance(step, int) or isinstance(step, bool) or step < 0:
        raise RetargetError(f"{path}: the checkpoint's step {str(step)[:40]!r} is not an integer >= 0")
    if (not isinstance(elapsed, (int, float)) or isinstance(elapsed, bool) or not math.isfinite(elapsed)
            or elapsed < 0):
        raise RetargetError(f"{path}: the checkpoint's elapsed_s {str(elapsed)[:40]!r} is not a "
                            "number >= 0")
    for key in ("optimizer", "train_config"):
        if key in state and not isinstance(state[key], dict):
            raise RetargetError(f"{path}: the checkpoint's {key} is not a mapping")
    for key, check, what in (("code_map", check_code_map, f"({cfg.code_dim}, {cfg.n_facs}) tensor "
                                                           "of a basis-decoder model"),
                             ("code_map_gate", check_gate, f"({cfg.code_dim + 1},) tensor beside a "
                                                           "code_map"),
                             ("code_map_error", check_map_error,
                              f"symmetric (1 or 2, {cfg.code_dim}, {cfg.code_dim}) tensor beside a "
                              "code_map")):
        if key not in state:
            continue
        ok = isinstance(state[key], torch.Tensor) and "code_map" in state   # a gate needs a map
        try:
            ok = ok and check(state[key].detach().cpu().numpy(), cfg) is not None
        except ValueError:
            ok = False
        if not ok:
            raise RetargetError(f"{path}: the checkpoint's {key} is not a finite {what}")
    head_keys = [k for k in ("code_map_features", "code_map_slopes") if k in state]
    if head_keys:
        ok = len(head_keys) == 2 and "code_map" in state and all(
            isinstance(state[k], torch.Tensor) for k in head_keys)
        try:
            ok = ok and check_per_head(tuple(state[k].detach().cpu().numpy() for k in head_keys),
                                       cfg) is not None
        except ValueError:
            ok = False
        if not ok:
            raise RetargetError(f"{path}: the checkpoint's per-head code map is not a pair of finite "
                                f"tensors code_map_features (d + 1, {cfg.code_dim}) and "
                                f"code_map_slopes (d, {cfg.code_dim}, {cfg.n_facs}) beside a "
                                "code_map")


def checkpoint_code_map(state: dict):
    """The checked checkpoint's code map (code_dim, 53), its gate (code_dim + 1,), its per-head
    part (features (d + 1, code_dim), slopes (d, code_dim, 53)) and its error moments (K,
    code_dim, code_dim), float32 numpy arrays (``retarget.code_map``); None for what it lacks."""
    code_map, gate, features, slopes, error = (
        None if state.get(k) is None else state[k].detach().cpu().float().numpy()
        for k in ("code_map", "code_map_gate", "code_map_features", "code_map_slopes",
                  "code_map_error"))
    return code_map, gate, (None if features is None else (features, slopes)), error


def put_code_map(state: dict, code_map: np.ndarray, gate: np.ndarray | None,
                 per_head: tuple | None = None, error: np.ndarray | None = None) -> dict:
    """``state`` with a code map (code_dim, 53), its gate (code_dim + 1,) or None (no gate), its
    per-head part (features, slopes) or None and its error moments (K, code_dim, code_dim) or None
    put in as the tensors ``checkpoint_code_map`` reads back; returns ``state``."""
    state["code_map"] = torch.from_numpy(np.asarray(code_map, np.float32))
    if error is not None:
        state["code_map_error"] = torch.from_numpy(np.asarray(error, np.float32))
    if gate is not None:
        state["code_map_gate"] = torch.from_numpy(np.asarray(gate, np.float32))
    if per_head is not None:
        state["code_map_features"] = torch.from_numpy(np.asarray(per_head[0], np.float32))
        state["code_map_slopes"] = torch.from_numpy(np.asarray(per_head[1], np.float32))
    return state


def model_from_checkpoint(state: dict, path="checkpoint") -> NFSModel:
    """Build the NFSModel of a loaded checkpoint and load its weights. The shapes its config gives
    are compared with the weights held on the ``meta`` device first (no memory), so a config that
    claims another (or a huge) model is refused before it is built."""
    cfg = checkpoint_config(state, path)
    held = state.get("model")
    try:
        with torch.device("meta"):
            expected = {k: tuple(v.shape) for k, v in NFSModel(cfg).state_dict().items()}
        if not isinstance(held, dict):
            raise KeyError("model")
        got = {k: tuple(v.shape) for k, v in held.items()}
        if got != expected:
            diff = sorted(set(got) ^ set(expected)) or [k for k in expected if got[k] != expected[k]]
            raise ValueError(f"{diff[0]}: the config gives {expected.get(diff[0])}, the file holds "
                             f"{got.get(diff[0])}")
        model = NFSModel(cfg)
        model.load_state_dict(held)
    except (KeyError, ValueError, RuntimeError, AttributeError) as e:
        raise RetargetError(f"{path}: checkpoint does not match this version's model "
                            f"({str(e).splitlines()[0][:200]})") from None
    return model


#: The DiffusionNet encoders, which ``warm_start`` widens to a larger ``NFSConfig.enc_width``.
ENCODERS = ("identity_encoder", "expression_encoder", "skinning_encoder", "blind_encoder")


def widen_encoder_tensor(key: str, src: torch.Tensor, dst: torch.Tensor, old: int, new: int) -> None:
    """Write a trained DiffusionNet tensor ``src`` (width ``old``) into ``dst``, the same tensor of a
    wider net (width ``new``), so that the wider net computes what the trained one did. key: the
    name inside the net (``first.weight``, ``blocks.0.mlp.0.weight``, ...); dst holds its fresh
    initialisation.

    The new channels start at zero and stay there until training moves them: what writes them
    (the first layer's and each block's last MLP layer's new rows) starts at zero. What reads
    them (A, the blocks' first MLP layer, the last layer) keeps its random initialisation, so
    gradients reach them; it multiplies zeros. So do the blocks' new hidden units, whose
    outgoing weights start at zero. The gradient features of a zero channel are tanh(0) = 0, and
    the blocks' MLP input [x, diffused x, gradient features] is widened segment by segment."""
    if key.startswith("first.") or ".mlp.3." in key:   # writers of the channels; first.weight
        _embed(src, dst, zero=True)                      # (W, c_in) may also take new inputs
    elif key.endswith("mlp.0.weight"):                 # (W, 3W): three segments of W inputs
        for k in range(3):
            dst[:old, k * new:k * new + old] = src[:, k * old:(k + 1) * old]
    elif key.startswith("last.") or key.endswith(("log_time", "A_re.weight", "A_im.weight",
                                                    "mlp.0.bias")):
        _embed(src, dst, zero=False)
    else:
        raise ValueError(f"warm_start: no rule to widen encoder tensor {key}")


def _embed(src: torch.Tensor, dst: torch.Tensor, zero: bool) -> None:
    """``src`` written into the leading block of the larger ``dst`` of the same rank; the rest of
    ``dst`` zeroed when ``zero``, else kept."""
    if zero:
        dst.zero_()
    dst[tuple(slice(0, n) for n in src.shape)] = src


#: What ``NFSConfig.skin_descriptor`` widens, and along which dim: the skinning encoder's last
#: layer gains F output rows and the decoder's first layer F input columns after z_Skin, all at
#: zero: the new channels start at sigmoid(0) = 0.5 everywhere and the decoder ignores them, so the
#: model computes what it did. L_corr moves the rows first (unbounded random rows saturate the
#: sigmoid), the decoder's columns follow from L_rig and L_dec.
DESCRIPTOR_TENSORS = {"skinning_encoder.last.weight": 0, "skinning_encoder.last.bias": 0,
                      "decoder.0.weight": 1}


def widens_descriptor(src: torch.Tensor, dst: torch.Tensor, dim: int) -> bool:
    """Whether ``dst`` is ``src`` with more rows (dim 0) or columns (dim 1), nothing else changed."""
    return (src.dim() == dst.dim() and src.shape[dim] < dst.shape[dim]
            and all(a == b for i, (a, b) in enumerate(zip(src.shape, dst.shape)) if i != dim))


def warm_start(model: NFSModel, initial: NFSModel, fresh: tuple[str, ...] = ()
               ) -> dict[str, list[str]]:
    """Copy into ``model`` the weights of ``initial``, a model of another config (a new design
    started from a trained one), and return what was done: {"copied": [...], "widened": [...],
    "narrowed": [...], "fresh": [...]} parameter names.

    A tensor is copied when its name and shape agree, except the decoder's when the two decoders
    differ in kind (``mlp`` / ``basis``: the same shapes mean different things). The expression
    encoder's first layer, widened by the neutral channels (``NFSConfig.neutral_channels``, appended
    after [v, c]), takes the old columns and zeros for the new ones, so the warm-started encoder
    computes what the old one did until training moves it; narrowed (a model without the neutral
    channels started from one with them: the ``no_neutral`` ablation at the same budget), it keeps
    the old columns of [v, c], and the no-neutral flag's column, which is 1 whenever the neutral is
    unknown, goes into the bias: the narrowed encoder computes what the old one did without the
    neutral (``narrowed`` in the report). The three DiffusionNet encoders of a
    larger ``enc_width`` (the same number of blocks) are widened the same way
    (``widen_encoder_tensor``). A model with more skinning descriptor channels
    (``NFSConfig.skin_descriptor``) takes the old rows and columns of ``DESCRIPTOR_TENSORS``;
    its decoder reads the new channels through zero columns, so it computes what the old model
    did. A model with a blind encoder (``NFSConfig.blind_encoder``) started from one without
    takes the old expression encoder for it, narrowed as above when the old one reads the
    neutral channels: it computes what the old model did without the neutral. Everything else
    keeps its fresh
    initialisation, except a fresh decoder's last layer, which starts at zero: the warm-started
    model first predicts no displacement (doing nothing) rather than a random field whose large
    first gradients would pull the copied encoders around.

    ``fresh``: top-level module names (``decoder``, ``skinning_encoder``, ...) to start fresh even
    where they fit (a same-budget comparison of a new module against a trained one); a fresh
    decoder's last layer starts at zero as above."""
    old = initial.state_dict()
    new = model.state_dict()
    known = {name.split(".")[0] for name in new}
    unknown = sorted(set(fresh) - known)
    if unknown:
        raise ValueError(f"no module {', '.join(unknown)} in the model (modules: "
                         f"{', '.join(sorted(known))})")
    fresh = set(fresh) | ({"decoder"} if model.cfg.decoder != initial.cfg.decoder else set())
    widths = (initial.cfg.enc_width, model.cfg.enc_width)
    report: dict[str, list[str]] = {"copied": [], "widened": [], "narrowed": [], "fresh": []}
    if model.cfg.blind_encoder and not initial.cfg.blind_encoder:
        old = {**old, **{"blind_encoder." + k.split(".", 1)[1]: v for k, v in old.items()
                         if k.startswith("expression_encoder.")}}
    narrowed_bias = []
    with torch.no_grad():
        for name, tensor in new.items():
            src = old.get(name)
            if src is None or name.split(".")[0] in fresh:
                report["fresh"].append(name)
            elif src.shape == tensor.shape:
                tensor.copy_(src)
                report["copied"].append(name)
            elif (name == "expression_encoder.first.weight" and src.dim() == 2
                  and src.shape[0] == tensor.shape[0] and src.shape[1] < tensor.shape[1]):
                _embed(src, tensor, zero=True)
                report["widened"].append(name)
            elif (name in ("expression_encoder.first.weight", "blind_encoder.first.weight")
                  and src.dim() == 2 and src.shape[0] == tensor.shape[0]
                  and src.shape[1] == tensor.shape[1] + NEUTRAL_CHANNEL_DIM):
                tensor.copy_(src[:, :tensor.shape[1]])
                report["narrowed"].append(name)
                narrowed_bias.append((name.replace(".weight", ".bias"), src[:, -1]))
            elif (name in DESCRIPTOR_TENSORS
                  and widens_descriptor(src, tensor, DESCRIPTOR_TENSORS[name])):
                _embed(src, tensor, zero=True)
                report["widened"].append(name)
            elif (name.split(".")[0] in ENCODERS and widths[0] < widths[1]
                  and model.cfg.enc_blocks == initial.cfg.enc_blocks):
                widen_encoder_tensor(name.split(".", 1)[1], src, tensor, *widths)
                report["widened"].append(name)
            else:
                report["fresh"].append(name)
        for bias, flag_column in narrowed_bias:   # flag 1 (no neutral) times its column, now a
            new[bias] += flag_column                 # constant
        if "decoder" in fresh:   # (the state dict's tensors are the model's own: no load needed)
            model.decoder[-1].weight.zero_()
            model.decoder[-1].bias.zero_()
    return report

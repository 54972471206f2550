"""The Neural Face Skinning network (Cha et al. 2025, section 3.1, Figure 4).

Inputs are a source mesh M_src (or FACS weights) and a target neutral mesh M_tgt; the output is a
displacement Δv (V_tgt, 3) for every target vertex, in the canonical units of the vertex features.

- image code c = CNN(frontal render) ∈ R^128, concatenated to every vertex feature v ∈ R^6
  (canonical position + unit normal);
- identity encoder: DiffusionNet on M_tgt, area-weighted mean -> z_ID ∈ R^128 (first J dims
  supervised by the identity coefficients);
- expression encoder: DiffusionNet on M_src, mean -> z_GE ∈ R^128 (first 53 dims = FACS weights);
- skinning encoder: DiffusionNet on M_tgt, per vertex, sigmoid -> z_Skin ∈ (0, 1)^L;
- skinning block: MLP z_Skin -> ω_Skin ∈ R^128 per vertex, z_LE = ω_Skin ⊙ z_GE;
- decoder: per-vertex MLP of 8 linear layers (GroupNorm + ReLU after all but the last) on
  [v_tgt, c_tgt, z_ID, z_LE] -> Δv (``decoder="mlp"``, the paper's); or, with ``decoder="basis"``,
  a per-vertex MLP on the target alone, [v_tgt, γ(x_tgt), c_tgt, z_ID, z_Skin] -> M(x) ∈
  R^(code_dim x 3), and Δv = M(x)ᵀ z_LE: linear in z_GE, a blendshape rig of code_dim shapes per
  target (γ = Fourier features of the canonical position). M, with ω_Skin folded in, is computed
  once per target (``TargetCodes.basis``), so each frame is one matrix-vector product.

Choices the paper leaves open (see ``NFSConfig``): one CNN shared by all encoders and the decoder
(the paper gives each encoder its own CNN; sharing lets the target image be encoded once); the
GroupNorm of the decoder normalises each vertex over channel groups (never across vertices), so
every vertex is decoded independently; ω_Skin has no output activation.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import torch
from torch import nn

from .cnn import FrontalCNN, group_norm
from .diffusion_net import DiffusionNet

CANONICAL_FRAMES = ("bbox", "face")   # NFSConfig.canonical (retarget.canonical.FRAMES)
VERTEX_FEATURE_DIM = 6  # canonical position (3) + unit vertex normal (3)
DECODERS = ("mlp", "basis")


#: Upper bounds of NFSConfig's integer fields: several times the paper's sizes, low enough that a
#: tampered or mistyped config (a checkpoint is not trusted) cannot ask for a model of terabytes
#: or an eigen-decomposition that never ends.
MAX_CONFIG_VALUES = dict(code_dim=2048, image_code_dim=2048, n_facs=2048, image_size=1024,
                         image_channels=16, cnn_width=512, enc_width=2048, enc_blocks=32, k_eig=512,
                         n_segments=256, skin_hidden=2048, skin_layers=32, decoder_width=2048,
                         decoder_layers=32, norm_groups=512, decoder_fourier=16,
                         skin_descriptor=256)
MIN_CONFIG_VALUES = dict(decoder_fourier=0, skin_descriptor=0)   # every other integer field is >= 1
#: allowed values of NFSConfig's string fields
STR_CHOICES = dict(canonical=CANONICAL_FRAMES, decoder=DECODERS)


def _expected(name: str, kind: str) -> str:
    """What NFSConfig field ``name`` of type ``kind`` accepts, for its error message."""
    if kind == "str":
        return f"one of {STR_CHOICES[name]}"
    if kind == "int":
        return f"an int in {MIN_CONFIG_VALUES.get(name, 1)}..{MAX_CONFIG_VALUES[name]}"
    return f"a {kind}"

#: Extra per-vertex inputs of the neutral-aware expression encoder (``NFSConfig.neutral_channels``):
#: displacement from the source's neutral (3, canonical units), change of the unit vertex normal (3),
#: and a flag that is 1 when no neutral was given (then the other six are 0).
NEUTRAL_CHANNEL_DIM = 7


@dataclass(frozen=True)
class NFSConfig:
    """Every dimension and switch of ``NFSModel``; plain types only (checkpoint friendly).

    Attributes:
        code_dim: size of z_ID, z_GE, z_LE and ω_Skin (128 in the paper).
        image_code_dim: size of the image code c (128 in the paper).
        n_facs: FACS weights carried by the first dims of z_GE (53, ICT-FaceKit order).
        image_size: H = W of the frontal renders, pixels.
        image_channels: channels of the frontal renders (e.g. 2 = shaded + depth).
        cnn_width: channels of the first CNN convolution.
        enc_width: DiffusionNet width of the three encoders.
        enc_blocks: DiffusionNet blocks of each encoder.
        k_eig: Laplacian eigenpairs the operators must provide (the spectral diffusion basis).
        dropout: DiffusionNet dropout probability.
        n_segments: L, segmentation labels = channels of z_Skin (6, 14, 20 or 24 in the paper).
        skin_hidden: hidden width of the skinning block MLP.
        skin_layers: linear layers of the skinning block MLP (ReLU between them).
        decoder_width: hidden width of the decoder.
        decoder_layers: linear layers of the decoder (8 in the paper).
        norm_groups: GroupNorm groups in the decoder and the CNN.
        use_skinning: False = the "without skinning encoder" ablation (NFR-like): no skinning
            encoder or block, the decoder takes z_GE broadcast to every vertex.
        canonical: the canonical frame the model was trained in (``retarget.canonical``):
            "bbox" (bounding box; every checkpoint without the key) or "face" (fitted to the face).
        decoder: "mlp" = the paper's decoder, nonlinear in the code; "basis" = a per-vertex
            basis M(x) (code_dim x 3) from the target's features, Δv = M(x)ᵀ z_LE (Δv = M(x)ᵀ z_GE
            without skinning). Checkpoints older than the field load as "mlp".
        decoder_fourier: octaves of Fourier features sin/cos(2^k π x / 8), k < decoder_fourier, of
            the canonical position (a 16-unit-wide head) added to the basis decoder's input; 0 =
            none. Only the basis decoder reads it.
        neutral_channels: beyond the paper: the expression encoder also takes, per source vertex,
            its displacement from the source's neutral and the change of its normal, or zeros and
            a flag channel when the neutral is unknown (``NEUTRAL_CHANNEL_DIM``). False = the
            paper's encoder (and every checkpoint saved before the field existed).
        skin_descriptor: beyond the paper: F extra per-vertex output channels of the skinning
            encoder, in (0, 1) like z_Skin, that the basis decoder reads with it (its input
            [v, γ(x), c, z_ID, z_Skin, descriptor]) and nothing else does: a learned description
            of where on the face each target vertex lies, finer than the L segments, so that
            M(x) can place each FACS shape on a new identity. 0 = none (every checkpoint saved
            before the field existed). Needs the basis decoder with skinning.
        blind_encoder: beyond the paper, with ``neutral_channels``: a second expression encoder,
            the paper's (input [v, c], no neutral channels), that reads the sources whose neutral
            is unknown; the neutral-aware encoder then reads only sources with their neutral. The
            two readings share no weight (docs/RESULTS.md, "Stage 21"). False = one encoder for
            both (every checkpoint saved before the field).
    """

    code_dim: int = 128
    image_code_dim: int = 128
    n_facs: int = 53
    image_size: int = 64
    image_channels: int = 2
    cnn_width: int = 16
    enc_width: int = 64
    enc_blocks: int = 4
    k_eig: int = 64
    dropout: float = 0.0
    n_segments: int = 20
    skin_hidden: int = 64
    skin_layers: int = 3
    decoder_width: int = 128
    decoder_layers: int = 8
    norm_groups: int = 8
    use_skinning: bool = True
    canonical: str = "bbox"
    decoder: str = "mlp"
    decoder_fourier: int = 0
    neutral_channels: bool = False
    skin_descriptor: int = 0
    blind_encoder: bool = False

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.type == "bool":
                ok = isinstance(value, bool)
            elif f.type == "str":
                ok = value in STR_CHOICES[f.name]
            elif f.type == "float":
                ok = isinstance(value, (int, float)) and not isinstance(value, bool)
            else:
                ok = (isinstance(value, int) and not isinstance(value, bool)
                      and MIN_CONFIG_VALUES.get(f.name, 1) <= value <= MAX_CONFIG_VALUES[f.name])
            if not ok:
                raise ValueError(f"NFSConfig.{f.name}: expected {_expected(f.name, f.type)}, "
                                 f"got {str(value)[:40]!r}")
        if self.n_facs > self.code_dim:
            raise ValueError(f"NFSConfig: n_facs ({self.n_facs}) must not exceed code_dim "
                             f"({self.code_dim})")
        if self.skin_descriptor and (self.decoder != "basis" or not self.use_skinning):
            raise ValueError("NFSConfig.skin_descriptor needs decoder 'basis' with use_skinning")
        if self.blind_encoder and not self.neutral_channels:
            raise ValueError("NFSConfig.blind_encoder needs neutral_channels (without them the "
                             "one expression encoder is already the paper's)")
        if self.decoder_layers < 2:
            raise ValueError(f"NFSConfig.decoder_layers must be >= 2, got {self.decoder_layers}")
        if not 0.0 <= self.dropout < 1.0:  # NaN too
            raise ValueError(f"NFSConfig.dropout must be in [0, 1), got {self.dropout}")

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> "NFSConfig":
        """A named configuration, optionally with fields replaced.

        - ``"paper"``: the paper's sizes where it states them (codes 128, DiffusionNet width 256 with
          4 blocks, 8 decoder layers) and the authors' public code's otherwise (decoder and
          skinning-block width 256, GroupNorm 32 groups); 256² renders, k = 128. The CNN width (32)
          is our choice, as is dropout 0 in every preset.
        - ``"cpu"``: the defaults (DiffusionNet width 64 with 4 blocks, decoder width 128, 64²
          renders, k = 64, 0.62 M parameters), sized for training on a 2-core CPU in about two
          hours: one thread, one target with 8 sources and 1000 decoded vertices, forward +
          backward + AdamW step took 73 ms per sample at 2.5k target vertices and 237 ms at 10k.
        - ``"tiny"``: for tests (encoder widths 16, 1 block, decoder width 32 — narrower does not
          fit even one training group —, 32² renders, k = 16).
        """
        if name not in _PRESETS:
            raise ValueError(f"unknown NFSConfig preset {name!r}; choose one of {sorted(_PRESETS)}")
        return cls.from_dict({**_PRESETS[name], **overrides})

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of ints, floats and bools (loadable with ``torch.load(weights_only=True)``)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "NFSConfig":
        """Inverse of ``to_dict``; missing keys take the defaults, unknown keys raise ValueError.
        Keys of earlier versions that no longer mean anything (``_RETIRED_KEYS``) are dropped."""
        if not isinstance(d, dict):
            raise TypeError(f"NFSConfig: expected a mapping of settings, got a {type(d).__name__}")
        d = {k: v for k, v in d.items() if k not in _RETIRED_KEYS}
        unknown = sorted(set(d) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise ValueError(f"NFSConfig: unknown keys {unknown} (a checkpoint or config from "
                             f"another version?)")
        return cls(**d)


#: NFSConfig fields that were removed: ``n_identity`` (the identity loss takes the number of identity
#: coefficients from the rig; the model never used it), still present in older checkpoints.
_RETIRED_KEYS = ("n_identity",)

_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(image_size=256, cnn_width=32, enc_width=256, enc_blocks=4, k_eig=128,
                  skin_hidden=256, decoder_width=256, norm_groups=32),
    "cpu": {},
    "tiny": dict(image_size=32, cnn_width=8, enc_width=16, enc_blocks=1, k_eig=16,
                 skin_hidden=16, decoder_width=32, norm_groups=4),
}


def weights_to_code(w: torch.Tensor, code_dim: int = 128) -> torch.Tensor:
    """FACS weights -> expression code for driving the decoder: z_GE = [w, 0].

    Args:
        w: (..., 53) float, ICT-FaceKit order, nominally in [0, 1].
        code_dim: size of z_GE.
    Returns:
        (..., code_dim) with the weights in the first dims and zeros in the rest.
    """
    if w.shape[-1] > code_dim:
        raise ValueError(f"weights_to_code: {w.shape[-1]} weights do not fit a {code_dim}-dim code")
    return torch.cat([w, w.new_zeros(*w.shape[:-1], code_dim - w.shape[-1])], dim=-1)


def _chunks(n: int, chunk: int | None) -> list[slice]:
    """Consecutive slices covering range(n), each of at most ``chunk`` items (None = one slice)."""
    if chunk is not None and chunk < 1:
        raise ValueError(f"decode: chunk must be >= 1, got {chunk}")
    step = n if chunk is None else chunk
    return [slice(i, min(i + step, n)) for i in range(0, n, max(step, 1))]


def mlp(dims: Sequence[int], norm_groups: int | None = None) -> nn.Sequential:
    """Linear layers ``dims[0] -> dims[1] -> ... -> dims[-1]`` applied to the last axis.

    After every layer but the last: GroupNorm (when ``norm_groups`` is given) and ReLU.
    On (N, C) inputs each row is processed independently.
    """
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        layers.append(nn.Linear(a, b))
        if i < len(dims) - 2:
            if norm_groups is not None:
                layers.append(group_norm(b, norm_groups))
            layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


@dataclass
class TargetCodes:
    """What NFS computes once per target mesh and reuses for every source expression.

    Attributes:
        z_id: (code_dim,) identity code z_ID.
        z_skin: (V, L [+ F]) skinning feature z_Skin in (0, 1), followed by the F descriptor
            channels (``NFSConfig.skin_descriptor``), or None without skinning.
        omega_skin: (V, code_dim) skinning weights ω_Skin, cached for all the target's
            expressions; None without skinning, or to have ``local_code`` compute ω_Skin from
            z_skin chunk by chunk (no (V, code_dim) array kept, for huge meshes).
        basis: (V, 3, code_dim) the basis decoder's rig Bᵀ, B = ω_Skin ⊙ M(x) (M(x) without
            skinning), so Δv = Bᵀ z_GE per vertex (one (3V, code_dim) matrix-vector product per
            frame), in the units of the features' positions; None for the MLP decoder, or to have
            ``decode_target`` compute M chunk by chunk.
    """

    z_id: torch.Tensor
    z_skin: torch.Tensor | None
    omega_skin: torch.Tensor | None
    basis: torch.Tensor | None = None


class NFSModel(nn.Module):
    """Neural Face Skinning: encoders, skinning block and per-vertex decoder (see module doc).

    Every method takes one mesh at a time: ``feat`` (V, 6) float32 canonical position + unit normal,
    ``c`` (image_code_dim,) the image code of that mesh's neutral render, ``ops`` its
    ``nets.geometry.TorchOperators`` (with at least ``cfg.k_eig`` eigenpairs).
    """

    def __init__(self, cfg: NFSConfig):
        super().__init__()
        self.cfg = cfg
        c_in = VERTEX_FEATURE_DIM + cfg.image_code_dim
        self.cnn = FrontalCNN(cfg.image_channels, cfg.image_size, cfg.image_code_dim, cfg.cnn_width,
                              cfg.norm_groups)
        self.identity_encoder = DiffusionNet(c_in, cfg.code_dim, cfg.enc_width, cfg.enc_blocks,
                                             cfg.dropout, outputs="global_mean")
        self.expression_encoder = DiffusionNet(
            c_in + NEUTRAL_CHANNEL_DIM * cfg.neutral_channels, cfg.code_dim, cfg.enc_width,
            cfg.enc_blocks, cfg.dropout, outputs="global_mean")
        if cfg.blind_encoder:
            self.blind_encoder = DiffusionNet(c_in, cfg.code_dim, cfg.enc_width, cfg.enc_blocks,
                                              cfg.dropout, outputs="global_mean")
        if cfg.use_skinning:
            self.skinning_encoder = DiffusionNet(c_in, cfg.n_segments + cfg.skin_descriptor,
                                                 cfg.enc_width,
                                                 cfg.enc_blocks, cfg.dropout, outputs="vertices",
                                                 last_activation=torch.sigmoid)
            self.skinning_mlp = mlp([cfg.n_segments]
                                    + [cfg.skin_hidden] * (cfg.skin_layers - 1) + [cfg.code_dim])
        if cfg.decoder == "mlp":
            dims = [c_in + 2 * cfg.code_dim, 3]
        else:   # [v, γ(x), c, z_ID, z_Skin] -> M(x), code_dim x 3 per vertex
            dims = [c_in + 6 * cfg.decoder_fourier + cfg.code_dim
                    + (cfg.n_segments + cfg.skin_descriptor) * cfg.use_skinning, 3 * cfg.code_dim]
        self.decoder = mlp(dims[:1] + [cfg.decoder_width] * (cfg.decoder_layers - 1) + dims[1:],
                           cfg.norm_groups)

    # ----------------------------------------------------------------------------- encoders
    def image_code(self, img: torch.Tensor) -> torch.Tensor:
        """Frontal renders (B, C, H, W) float32 in [0, 1] -> image codes c (B, image_code_dim)."""
        return self.cnn(img)

    def _encode(self, net: DiffusionNet, x: torch.Tensor, c: torch.Tensor, ops) -> torch.Tensor:
        """An encoder on the input [v, c, (neutral channels)] per vertex: x the per-vertex columns
        (V, 6 [+ NEUTRAL_CHANNEL_DIM]), c (image_code_dim,) the same at every vertex, after v."""
        self._check_image_code(c)
        return net(x, ops, constant=c, constant_at=VERTEX_FEATURE_DIM)

    @staticmethod
    def _check_features(feat: torch.Tensor) -> None:
        """ValueError unless feat is (V, 6)."""
        if feat.dim() != 2 or feat.shape[1] != VERTEX_FEATURE_DIM:
            raise ValueError(f"vertex features must be (V, {VERTEX_FEATURE_DIM}); got "
                             f"{tuple(feat.shape)}")

    def _check_image_code(self, c: torch.Tensor) -> None:
        """ValueError unless c is one image code (image_code_dim,)."""
        if c.shape != (self.cfg.image_code_dim,):
            raise ValueError(f"image code c must be ({self.cfg.image_code_dim},); got "
                             f"{tuple(c.shape)} (use image_code(img)[0] for one image)")

    def encode_identity(self, feat: torch.Tensor, c: torch.Tensor, ops) -> torch.Tensor:
        """Identity encoder on a neutral mesh -> z_ID (code_dim,) (area-weighted vertex mean)."""
        self._check_features(feat)
        return self._encode(self.identity_encoder, feat, c, ops)

    def encode_expression(self, feat: torch.Tensor, c: torch.Tensor, ops,
                          neutral: torch.Tensor | None = None, blind: bool = True) -> torch.Tensor:
        """Expression encoder on an expression mesh -> z_GE (code_dim,); z_GE[:53] = FACS weights.

        ``c`` is the image code of the mesh's *neutral* render and ``ops`` may be the neutral's
        operators, as in the paper. ``neutral``: (V, NEUTRAL_CHANNEL_DIM) channels relative to the
        source's neutral (``retarget.prepare.neutral_channels``), or None when it is unknown; used
        only by a model with ``cfg.neutral_channels`` (ignored otherwise). A model with
        ``cfg.blind_encoder`` reads a source without its neutral by its second encoder, unless
        ``blind`` is False (then by the neutral-aware one, its flag set, as a model without it).
        """
        if neutral is None and self.cfg.blind_encoder and blind:
            self._check_features(feat)
            return self._encode(self.blind_encoder, feat, c, ops)
        return self._encode(self.expression_encoder, self.expression_input(feat, neutral), c, ops)

    def expression_input(self, feat: torch.Tensor, neutral: torch.Tensor | None = None) -> torch.Tensor:
        """The per-vertex columns of the expression encoder's input [v, c, neutral channels] (the
        image code c is the same at every vertex and enters the first layer once): v (V, 6), and
        with ``cfg.neutral_channels`` the neutral channels after it (zeros and flag 1 when
        ``neutral`` is None) -> (V, 6 [+ NEUTRAL_CHANNEL_DIM])."""
        self._check_features(feat)
        x = feat
        if not self.cfg.neutral_channels:
            return x
        if neutral is None:
            neutral = feat.new_zeros(feat.shape[0], NEUTRAL_CHANNEL_DIM)
            neutral[:, -1] = 1.0
        elif neutral.shape != (feat.shape[0], NEUTRAL_CHANNEL_DIM):
            raise ValueError(f"neutral channels must be ({feat.shape[0]}, {NEUTRAL_CHANNEL_DIM}); "
                             f"got {tuple(neutral.shape)}")
        return torch.cat([x, neutral], dim=1)

    def encode_skinning(self, feat: torch.Tensor, c: torch.Tensor, ops) -> torch.Tensor:
        """Skinning encoder on a neutral mesh -> z_Skin (V, L) in (0, 1) (sigmoid, for eq. 2 BCE),
        followed by the ``cfg.skin_descriptor`` descriptor channels: (V, L + F)."""
        self._require_skinning()
        self._check_features(feat)
        return self._encode(self.skinning_encoder, feat, c, ops)

    def skinning_weights(self, z_skin: torch.Tensor) -> torch.Tensor:
        """Skinning block MLP: z_Skin (V, L [+ F]) -> ω_Skin (V, code_dim) (no output activation);
        it reads the L segment channels only."""
        self._require_skinning()
        return self.skinning_mlp(z_skin[..., :self.cfg.n_segments])

    def skinning_block(self, z_skin: torch.Tensor, z_ge: torch.Tensor) -> torch.Tensor:
        """Skinning block Ψ: z_LE = ω_Skin ⊙ z_GE; z_skin (V, L [+ F]), z_ge (code_dim,) -> (V, code_dim)."""
        return self.skinning_weights(z_skin) * z_ge

    def encode_target(self, feat: torch.Tensor, c: torch.Tensor, ops, basis: bool = True,
                      chunk: int | None = None) -> TargetCodes:
        """z_ID, z_Skin and ω_Skin of a target neutral mesh, computed once for all its expressions,
        and, for the basis decoder when ``basis`` is True, its rig (``with_basis``, ``chunk``
        vertices at a time)."""
        z_id = self.encode_identity(feat, c, ops)
        if not self.cfg.use_skinning:
            codes = TargetCodes(z_id, None, None)
        else:
            z_skin = self.encode_skinning(feat, c, ops)
            codes = TargetCodes(z_id, z_skin, self.skinning_weights(z_skin))
        return self.with_basis(feat, c, codes, chunk) if basis else codes

    def with_basis(self, feat: torch.Tensor, c: torch.Tensor, codes: TargetCodes,
                   chunk: int | None = None) -> TargetCodes:
        """``codes`` with ``basis`` (V, 3, code_dim) = (ω_Skin ⊙ M(x))ᵀ filled in for the V vertices of
        ``feat`` (V, 6) (``codes`` must describe the same vertices), computed ``chunk`` vertices at
        a time, with ω_Skin folded in (the cached one, or computed per chunk from z_Skin when
        ``codes.omega_skin`` is None); the other fields are kept. ``codes`` unchanged for the MLP
        decoder."""
        if self.cfg.decoder != "basis":
            return codes
        self._check_image_code(c)
        bias = self._decoder_bias(c, codes.z_id)
        basis = feat.new_empty(feat.shape[0], 3, self.cfg.code_dim)   # filled in place: no 2x peak
        for rows in _chunks(feat.shape[0], chunk):
            z_skin = None if codes.z_skin is None else codes.z_skin[rows]
            m = self._basis_rows(feat[rows], z_skin, bias)                 # (n, code_dim, 3)
            if self.cfg.use_skinning:
                omega = (codes.omega_skin[rows] if codes.omega_skin is not None
                         else self.skinning_weights(z_skin))
                m = m * omega[:, :, None]
            basis[rows] = m.transpose(1, 2)
        return dataclasses.replace(codes, basis=basis)

    def local_code(self, codes: TargetCodes, z_ge: torch.Tensor,
                   rows: torch.Tensor | slice | None = None) -> torch.Tensor:
        """The decoder's expression input on the target: z_LE (n, code_dim) = ω_Skin[rows] ⊙ z_GE,
        or z_GE (code_dim,) itself without skinning (the decoder broadcasts it); for S codes z_ge
        (S, code_dim): (S, n, code_dim), or z_ge itself.

        rows: (n,) int64 vertex indices or a slice, None for all V vertices. When
        ``codes.omega_skin`` is None, ω_Skin is computed from ``codes.z_skin`` for these rows only
        (no (V, code_dim) array is kept: the low-memory path for huge meshes).
        """
        if not self.cfg.use_skinning:
            return z_ge
        pick = (lambda a: a) if rows is None else (lambda a: a[rows])
        z = z_ge[..., None, :] if z_ge.dim() == 2 else z_ge      # S codes: (S, 1, code_dim)
        if codes.omega_skin is not None:
            return pick(codes.omega_skin) * z
        return self.skinning_block(pick(codes.z_skin), z)

    # ----------------------------------------------------------------------------- decoder
    def _decoder_bias(self, c: torch.Tensor, z_id: torch.Tensor) -> torch.Tensor:
        """The decoder's first layer bias with its c and z_ID columns folded in (width,): they are
        the same for every vertex of a target (2/3 of that layer's work per row saved)."""
        first, d = self.decoder[0], self.cfg.code_dim
        start = VERTEX_FEATURE_DIM + (6 * self.cfg.decoder_fourier if self.cfg.decoder == "basis"
                                      else 0)
        w_const = first.weight[:, start:start + self.cfg.image_code_dim + d]
        return torch.addmv(first.bias, w_const, torch.cat([c, z_id]))

    def _basis_rows(self, feat: torch.Tensor, z_skin: torch.Tensor | None,
                    bias: torch.Tensor) -> torch.Tensor:
        """The basis decoder's M(x) (n, code_dim, 3) of n vertices: feat (n, 6), z_skin (n, L) (None
        without skinning), bias from ``_decoder_bias``."""
        first, k = self.decoder[0], self.cfg.decoder_fourier
        x = feat
        if k:
            ang = feat[:, None, :3] * (torch.pi / 8 * 2.0 ** torch.arange(k, device=feat.device)
                                       )[:, None]                          # (n, k, 3)
            x = torch.cat([feat, ang.sin().flatten(1), ang.cos().flatten(1)], dim=1)
        n_x, n_const = x.shape[1], self.cfg.image_code_dim + self.cfg.code_dim
        h = x @ first.weight[:, :n_x].T + bias
        if self.cfg.use_skinning:
            if z_skin is None:
                raise ValueError("the basis decoder with skinning needs z_Skin (TargetCodes.z_skin)")
            h = h + z_skin @ first.weight[:, n_x + n_const:].T
        return self.decoder[1:](h).reshape(feat.shape[0], self.cfg.code_dim, 3)

    def decode(self, feat: torch.Tensor, c: torch.Tensor, z_id: torch.Tensor, z_code: torch.Tensor,
               chunk: int | None = None, z_skin: torch.Tensor | None = None) -> torch.Tensor:
        """Per-vertex decoder D: [v, c, z_ID, z_code] -> Δv (the basis decoder: Δv = M(x)ᵀ z_code
        with M from [v, γ(x), c, z_ID, z_Skin]).

        Args:
            feat: (V, 6) target vertex features (any subset of the target's rows).
            c: (image_code_dim,) target image code.
            z_id: (code_dim,) target identity code z_ID.
            z_code: (V, code_dim) z_LE, or (code_dim,) z_GE broadcast to all rows (no skinning).
            chunk: decode at most this many vertices at a time; the same result, and under
                ``torch.no_grad`` the working memory is that of one chunk.
            z_skin: (V, L [+ F]) z_Skin of these rows (with the descriptor channels): read by the
                basis decoder with skinning only.
        Returns:
            (V, 3) float32 displacement Δv in the units of ``feat``'s positions.
        """
        n, d = feat.shape[0], self.cfg.code_dim
        if z_id.shape != (d,) or z_code.shape not in ((n, d), (d,)):
            raise ValueError(f"decode: z_id must be ({d},) and z_code ({n}, {d}) or ({d},); got "
                             f"{tuple(z_id.shape)} and {tuple(z_code.shape)}")
        return self.decode_many(feat, c, z_id, z_code[None], chunk, z_skin)[0]

    def decode_many(self, feat: torch.Tensor, c: torch.Tensor, z_id: torch.Tensor,
                    z_codes: torch.Tensor, chunk: int | None = None,
                    z_skin: torch.Tensor | None = None) -> torch.Tensor:
        """``decode`` for S expressions of one target in one pass: z_codes (S, V, code_dim) z_LE or
        (S, code_dim) z_GE broadcast to all rows -> Δv (S, V, 3); ``chunk`` bounds the rows per
        pass (working memory S x chunk rows); ``z_skin`` (V, L [+ F]) as in ``decode``.

        The first linear layer is applied by parts: its columns for c and z_ID, the same for every
        row, are folded into a bias once per call, which removes 2/3 of that layer's work per row
        (equal to the layer on the concatenated input up to float rounding).
        """
        n, d = feat.shape[0], self.cfg.code_dim
        per_frame = z_codes.dim() == 2                                 # (S, d): no skinning
        if (z_id.shape != (d,) or z_codes.shape[-1] != d or z_codes.dim() not in (2, 3)
                or (not per_frame and z_codes.shape[1] != n)):
            raise ValueError(f"decode_many: z_id must be ({d},) and z_codes (S, {n}, {d}) or "
                             f"(S, {d}); got {tuple(z_id.shape)} and {tuple(z_codes.shape)}")
        self._check_image_code(c)
        bias = self._decoder_bias(c, z_id)                                        # (width,)
        if self.cfg.decoder == "basis":
            out = []
            for rows in _chunks(n, chunk):
                m = self._basis_rows(feat[rows], None if z_skin is None else z_skin[rows], bias)
                out.append(torch.einsum("sd,mdc->smc", z_codes, m) if per_frame
                           else torch.einsum("smd,mdc->smc", z_codes[:, rows], m))
            return torch.cat(out, dim=1) if out else feat.new_zeros(len(z_codes), 0, 3)
        first, rest = self.decoder[0], self.decoder[1:]
        w_v, w_code = first.weight[:, :VERTEX_FEATURE_DIM], first.weight[:, -d:]
        if per_frame:
            bias = (bias + z_codes @ w_code.T)[:, None]                           # (S, 1, width)
        out = []
        for rows in _chunks(n, chunk):
            h = (feat[rows] @ w_v.T)[None] + bias                                 # (S|1, m, width)
            if not per_frame:
                h = h + z_codes[:, rows] @ w_code.T                               # (S, m, width)
            s, m = h.shape[0], h.shape[1]
            out.append(rest(h.reshape(s * m, -1)).reshape(s, m, 3))
        return torch.cat(out, dim=1) if out else feat.new_zeros(len(z_codes), 0, 3)

    def decode_target(self, feat: torch.Tensor, c: torch.Tensor, codes: TargetCodes,
                      z_ge: torch.Tensor, rows: torch.Tensor | None = None,
                      chunk: int | None = None) -> torch.Tensor:
        """D(Ψ(z_GE, z_Skin)) on a target: Δv (n, 3) for an expression code z_ge (code_dim,), or
        (S, n, 3) for S codes (S, code_dim) decoded in one pass.

        ``feat`` (V, 6) and ``c`` are the target's, ``codes`` from ``encode_target``; rows (n,) int64
        selects the vertices to decode (None = all); ``chunk`` as in ``decode`` (z_LE is formed
        chunk by chunk too). Drive from FACS weights with ``z_ge = weights_to_code(w)``. With
        ``codes.basis`` (the basis decoder) this is one product (3n, code_dim) @ z_GE per frame.
        """
        if z_ge.dim() == 1:
            return self.decode_target(feat, c, codes, z_ge[None], rows, chunk)[0]
        n = feat.shape[0] if rows is None else rows.shape[0]
        out = []
        for part in _chunks(n, chunk):
            idx = part if rows is None else rows[part]
            if codes.basis is not None:
                b = codes.basis[idx]                                               # (m, 3, d)
                out.append((b.reshape(-1, b.shape[-1]) @ z_ge.T).T.reshape(len(z_ge), -1, 3))
                continue
            z_skin = None if codes.z_skin is None else codes.z_skin[idx]
            out.append(self.decode_many(feat[idx], c, codes.z_id, self.local_code(codes, z_ge, idx),
                                        z_skin=z_skin))
        return torch.cat(out, dim=1) if out else feat.new_zeros(len(z_ge), 0, 3)

    # ----------------------------------------------------------------------------- training
    def forward_group(self, tgt_feat: torch.Tensor, tgt_c: torch.Tensor, tgt_ops,
                      src_feats: Sequence[torch.Tensor], src_cs: Sequence[torch.Tensor],
                      src_ops: Sequence, vertex_subset: torch.Tensor | None = None
                      ) -> dict[str, torch.Tensor | None]:
        """Retarget S source meshes onto one target, encoding the target once.

        Args:
            tgt_feat, tgt_c, tgt_ops: the target neutral mesh (V, 6), (image_code_dim,), operators.
            src_feats, src_cs, src_ops: S source expression meshes (V_s, 6), their neutral's image
                codes and operators.
            vertex_subset: (n,) int64 target vertex indices to decode, or None for all V.
        Returns:
            dict with z_ID (code_dim,), z_Skin (V, L [+ F]) | None, z_GE (S, code_dim),
            z_LE (S, n, code_dim) | None, dv (S, n, 3).
        """
        if not len(src_feats) == len(src_cs) == len(src_ops) >= 1:
            raise ValueError("forward_group: need the same number (>= 1) of source features, "
                             "image codes and operators")
        codes = self.encode_target(tgt_feat, tgt_c, tgt_ops)
        sub = tgt_feat if vertex_subset is None else tgt_feat[vertex_subset]
        z_ge = torch.stack([self.encode_expression(f, c, o)
                            for f, c, o in zip(src_feats, src_cs, src_ops)])
        z_code = self.local_code(codes, z_ge, vertex_subset)       # (S, n, code_dim) or (S, code_dim)
        if codes.basis is not None:
            dv = self.decode_target(tgt_feat, tgt_c, codes, z_ge, vertex_subset)
        else:
            dv = self.decode_many(sub, tgt_c, codes.z_id, z_code)
        return {"z_ID": codes.z_id, "z_Skin": codes.z_skin, "z_GE": z_ge,
                "z_LE": z_code if self.cfg.use_skinning else None, "dv": dv}

    def forward_pair(self, src_feat: torch.Tensor, src_c: torch.Tensor, src_ops,
                     tgt_feat: torch.Tensor, tgt_c: torch.Tensor, tgt_ops,
                     vertex_subset: torch.Tensor | None = None) -> dict[str, torch.Tensor | None]:
        """Retarget one source mesh onto one target: ``forward_group`` with S = 1, squeezed.

        Returns dict with z_ID (code_dim,), z_GE (code_dim,), z_Skin (V, L [+ F]) | None,
        z_LE (n, code_dim) | None, dv (n, 3).
        """
        out = self.forward_group(tgt_feat, tgt_c, tgt_ops, [src_feat], [src_c], [src_ops],
                                 vertex_subset)
        for key in ("z_GE", "z_LE", "dv"):
            if out[key] is not None:
                out[key] = out[key][0]
        return out

    def _require_skinning(self):
        if not self.cfg.use_skinning:
            raise ValueError("this NFSModel was built with use_skinning=False (no skinning encoder)")


# ------------------------------------------------------------------------------------ benchmark
def benchmark_presets(presets: Sequence[str] = ("tiny", "cpu", "paper"),
                      sizes: Sequence[int] = (2000, 11000), repeats: int = 5) -> list[dict]:
    """Parameter count and the cost of one training sample for each preset and target size.

    One sample = one source and one target neutral (a wavy height field of about V vertices each,
    the same mesh for both), every target vertex decoded: image codes, the three encoders, the
    skinning block and the decoder forward, a squared-error loss on Δv, backward. Operators are
    computed beforehand (they are cached in training). Returns one dict per (preset, size):
    preset, n_params, n_vertices, forward_ms, backward_ms (medians over ``repeats`` runs after one
    warm-up run, on the current torch thread count, CPU).
    """
    import statistics
    import time

    from .geometry import _bumpy_grid, compute_operators, vertex_normals

    results = []
    for preset in presets:
        cfg = NFSConfig.preset(preset)
        torch.manual_seed(0)
        model = NFSModel(cfg)
        n_params = sum(p.numel() for p in model.parameters())
        for size in sizes:
            verts, faces = _bumpy_grid(size)
            ops = compute_operators(verts, faces, k=cfg.k_eig).to_torch()
            feat = torch.tensor(np.concatenate([verts, vertex_normals(verts, faces)], 1),
                                dtype=torch.float32)
            img = torch.rand(2, cfg.image_channels, cfg.image_size, cfg.image_size,
                             generator=torch.Generator().manual_seed(0))
            fwd, bwd = [], []
            for _ in range(repeats + 1):
                model.zero_grad(set_to_none=True)
                t0 = time.perf_counter()
                c_src, c_tgt = model.image_code(img)
                dv = model.forward_pair(feat, c_src, ops, feat, c_tgt, ops)["dv"]
                loss = dv.square().mean()
                t1 = time.perf_counter()
                loss.backward()
                t2 = time.perf_counter()
                fwd.append(t1 - t0)
                bwd.append(t2 - t1)
            results.append(dict(preset=preset, n_params=n_params, n_vertices=len(verts),
                                forward_ms=1000 * statistics.median(fwd[1:]),
                                backward_ms=1000 * statistics.median(bwd[1:])))
    return results


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="Parameters and per-sample training cost of the "
                                                 "NFSConfig presets (CPU).")
    parser.add_argument("--presets", nargs="+", default=["tiny", "cpu", "paper"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[2000, 11000])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    print("| preset | parameters | target vertices | forward (ms) | backward (ms) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for r in benchmark_presets(args.presets, args.sizes, args.repeats):
        print(f"| {r['preset']} | {r['n_params']:,} | {r['n_vertices']:,} | {r['forward_ms']:.1f} "
              f"| {r['backward_ms']:.1f} |")

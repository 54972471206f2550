"""Preparing a mesh for the network: canonical frame, vertex features, operators, frontal image.

The same preparation serves training (targets and sources of procedural rigs) and the user API
(``Retargeter.prepare``), so the network always sees meshes made the same way.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from nets.geometry import Operators, TorchOperators, load_or_compute_operators, vertex_normals

from .canonical import Canonicaliser
from .render import render_frontal


#: Frontal-render channels by channel count (the CNN input; nets.model.NFSConfig.image_channels).
IMAGE_CHANNELS = {1: ("shaded",), 2: ("shaded", "depth"), 4: ("normals", "depth")}


@dataclass
class PreparedMesh:
    """A mesh ready for the encoders and the decoder.

    canon: the canonicaliser fitted on the mesh (maps results back to the input's frame and units).
    vertices: (V,3) float32 canonical positions. faces: (F,3) int64.
    feat: (V,6) float32 per-vertex features v = [canonical position, unit vertex normal].
    ops: the DiffusionNet operators of the (canonical) surface.
    image: (C,H,W) float32 frontal render in [0,1] (the CNN input).
    normals: (V,3) float64 unit vertex normals of ``vertices`` (computed once, shared by the
    features, the render and the neutral channels), or None.
    The torch copies of ``ops`` are kept per device once made (a training target or source is used
    for many steps).
    """

    canon: Canonicaliser
    vertices: np.ndarray
    faces: np.ndarray
    feat: np.ndarray
    ops: Operators
    image: np.ndarray
    normals: np.ndarray | None = None
    _torch_ops: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    def torch_inputs(self, device) -> tuple[torch.Tensor, torch.Tensor, TorchOperators]:
        """(feat (V,6), image (1,C,H,W), operators) as tensors on ``device``."""
        feat = torch.from_numpy(self.feat).to(device)
        image = torch.from_numpy(self.image).unsqueeze(0).to(device)
        return feat, image, self.torch_ops(device)

    def torch_ops(self, device) -> TorchOperators:
        """``ops`` as float32 torch tensors on ``device``, made once per device."""
        key = str(torch.device(device))
        if key not in self._torch_ops:
            self._torch_ops[key] = self.ops.to_torch(device)
        return self._torch_ops[key]


def vertex_features(canonical_vertices: np.ndarray, faces: np.ndarray,
                    normals: np.ndarray | None = None) -> np.ndarray:
    """v = [position, unit normal] per vertex: (V,3) canonical positions -> (V,6) float32.
    ``normals``: their unit vertex normals (V,3) if computed already."""
    if normals is None:
        normals = vertex_normals(np.asarray(canonical_vertices, np.float64), faces)
    return np.concatenate([canonical_vertices, normals], axis=1).astype(np.float32)


def neutral_channels(frame: np.ndarray, neutral: np.ndarray, faces: np.ndarray,
                     frame_normals: np.ndarray | None = None,
                     neutral_normals: np.ndarray | None = None) -> np.ndarray:
    """The neutral-aware expression encoder's extra inputs (nets.model.NEUTRAL_CHANNEL_DIM = 7):
    frame (V,3) and its source's neutral (V,3), both in the neutral's canonical frame, faces (F,3)
    -> (V,7) float32 [frame − neutral, normal(frame) − normal(neutral), 0]; the last channel is the
    "no neutral" flag, 0 here (the model fills 0,..,0,1 itself when no neutral is given).
    ``frame_normals`` / ``neutral_normals``: their unit vertex normals (V,3) if computed already
    (a stream of frames reuses the neutral's)."""
    frame, neutral = np.asarray(frame, np.float64), np.asarray(neutral, np.float64)
    if frame.shape != neutral.shape:
        raise ValueError(f"neutral_channels: frame {frame.shape} and neutral {neutral.shape} differ")
    if frame_normals is None:
        frame_normals = vertex_normals(frame, faces)
    if neutral_normals is None:
        neutral_normals = vertex_normals(neutral, faces)
    d_normal = frame_normals - neutral_normals
    return np.concatenate([frame - neutral, d_normal, np.zeros((len(frame), 1))], 1).astype(np.float32)


def prepare_mesh(vertices: np.ndarray, faces: np.ndarray, k_eig: int, image_size: int,
                 image_channels: tuple[str, ...], canon: Canonicaliser | None = None,
                 ops: Operators | None = None, cache_dir=None,
                 canonical: str = "bbox") -> PreparedMesh:
    """Canonicalise a mesh and compute everything the network needs.

    vertices (V,3) in any units/offset, faces (F,3). ``canon``: reuse a canonicaliser (e.g. the
    neutral's, for its expression frames); default: fitted on these vertices, of the frame kind
    ``canonical`` (the model's ``NFSConfig.canonical``). The frontal image frames what the
    canonicaliser says (``Canonicaliser.render_fit``). ``ops``: reuse operators
    (an expression frame may reuse its neutral's, as the NFS authors do); default: computed on the
    canonical mesh and cached on disk by content hash (``cache_dir``, see nets.geometry).
    """
    faces = np.asarray(faces, np.int64)
    canon = canon or Canonicaliser.fit(vertices, kind=canonical, faces=faces)
    cv = canon.to_canonical(vertices).astype(np.float32)
    if ops is None:
        ops = load_or_compute_operators(cv, faces, k_eig, cache_dir=cache_dir)
    normals = vertex_normals(cv.astype(np.float64), faces)
    image = render_frontal(cv, faces, image_size, channels=tuple(image_channels), fit=canon.render_fit,
                           normals=normals)
    return PreparedMesh(canon, cv, faces, vertex_features(cv, faces, normals), ops, image, normals)

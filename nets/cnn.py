"""The frontal-render CNN of Neural Face Skinning (Cha et al. 2025, section 3.1).

A mesh is rendered from a fixed frontal camera (``retarget.render.render_frontal``: channels such as
shaded grey and depth, values in [0, 1]); this CNN maps the image to the image code
c ∈ R^128 that is concatenated to every vertex feature before the DiffusionNet encoders and the
decoder. NFS renders the *neutral* mesh of an identity once and reuses c for all its expressions;
the CNN itself just encodes the image it is given.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


class RowGroupNorm(nn.GroupNorm):
    """``nn.GroupNorm`` (same parameters and state dict) with a faster path for (N, C) inputs.

    On (N, C) each row is normalised on its own over each group of C/G channels, which is a layer
    norm of the (N, G, C/G) view followed by the per-channel affine. PyTorch's CPU group-norm kernel
    is slow for this shape (one "image" of spatial size 1 per row): on (9600, 128) with 8 groups,
    forward + backward took 19.7 ms with ``nn.GroupNorm`` and 10.2 ms this way (1 thread). Other
    shapes (the CNN's (B, C, H, W)) go through ``nn.GroupNorm``.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.dim() != 2:
            return super().forward(x)
        n, c = x.shape
        y = F.layer_norm(x.reshape(n, self.num_groups, c // self.num_groups),
                         (c // self.num_groups,), eps=self.eps).reshape(n, c)
        return torch.addcmul(self.bias, y, self.weight) if self.affine else y


def group_norm(channels: int, groups: int) -> nn.GroupNorm:
    """GroupNorm over ``channels`` with ``groups`` groups (reduced to the largest divisor <= groups).

    Used after convolutions here and after the decoder's linear layers in ``nets.model``; on a
    (N, C) input it normalises each row on its own, so per-vertex layers stay vertex-independent.
    """
    groups = max(g for g in range(1, min(groups, channels) + 1) if channels % g == 0)
    return RowGroupNorm(groups, channels)


class FrontalCNN(nn.Module):
    """Strided convolutional encoder: frontal render (B, C, H, W) -> image code c (B, out_dim).

    Layout: ``n_down = max(1, round(log2(image_size / 4)))`` blocks of 3x3 convolution with stride 2,
    GroupNorm and ReLU (channels ``width·2^i``, capped at ``8·width``), so a 256² image reaches 4²
    after 6 blocks and a 64² image after 4; then global average pooling and one linear layer.
    Images of another size than ``image_size`` still work (the pooling is global), but the network
    is meant to see the size it was trained on.

    Args:
        in_channels: C, number of image channels (e.g. 2 for shaded + depth).
        image_size: H = W of the renders, in pixels.
        out_dim: size of the image code c (128 in the paper).
        width: channels of the first convolution.
        norm_groups: GroupNorm groups.
    """

    def __init__(self, in_channels: int, image_size: int, out_dim: int = 128, width: int = 32,
                 norm_groups: int = 8):
        super().__init__()
        if in_channels < 1 or image_size < 4 or out_dim < 1 or width < 1:
            raise ValueError(
                f"FrontalCNN: need in_channels >= 1, image_size >= 4, out_dim >= 1, width >= 1; got "
                f"{in_channels}, {image_size}, {out_dim}, {width}")
        self.in_channels = in_channels
        n_down = max(1, round(math.log2(image_size / 4)))
        layers: list[nn.Module] = []
        c_prev = in_channels
        for i in range(n_down):
            c_next = width * 2 ** min(i, 3)
            layers += [nn.Conv2d(c_prev, c_next, 3, stride=2, padding=1),
                       group_norm(c_next, norm_groups), nn.ReLU(inplace=True)]
            c_prev = c_next
        self.features = nn.Sequential(*layers)
        self.head = nn.Linear(c_prev, out_dim)

    def forward(self, img: torch.Tensor) -> torch.Tensor:
        """img (B, C, H, W) float32 in [0, 1] -> c (B, out_dim) float32."""
        if img.dim() != 4 or img.shape[1] != self.in_channels:
            raise ValueError(
                f"FrontalCNN expects images of shape (B, {self.in_channels}, H, W); got "
                f"{tuple(img.shape)}")
        return self.head(self.features(img).mean(dim=(2, 3)))

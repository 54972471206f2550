"""Training losses of Neural Face Skinning (Cha et al. 2025, section 3.3-3.4, eq. 2-9).

Pure functions on tensors. Vertex arrays are (..., V, 3) with any leading batch dims, in the
canonical units the caller trains in (so a vertex loss is in those units squared). Every loss is a
scalar; the reduction is stated in each docstring.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

_EPS = 1e-12


def vertex_loss(pred: torch.Tensor, gt: torch.Tensor) -> torch.Tensor:
    """L_v = ||v - v_GT||² (eq. 3): squared Euclidean distance, mean over vertices (and batch).

    pred, gt: (..., V, 3). A constant offset d gives |d|².
    """
    return (pred - gt).pow(2).sum(-1).mean()


def face_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Area-weighted face normals: (v1 - v0) × (v2 - v0), length = 2·area.

    verts (..., V, 3), faces (F, 3) int64 -> (..., F, 3).
    """
    v0, v1, v2 = (verts[..., faces[:, i], :] for i in range(3))
    return torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)


def vertex_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Unit vertex normals, the area-weighted sum of the incident faces' normals (differentiable).

    verts (..., V, 3), faces (F, 3) int64 -> (..., V, 3); isolated vertices get zero normals.
    """
    fn = face_normals(verts, faces)
    n = torch.zeros_like(verts)
    for i in range(3):
        n = n.index_add(-2, faces[:, i], fn)
    return n / n.norm(dim=-1, keepdim=True).clamp_min(_EPS)


def normal_loss(pred: torch.Tensor, gt: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """L_n = ||n - n_GT||² (eq. 3) between unit vertex normals of the predicted and GT meshes.

    pred, gt: (..., V, 3) deformed vertices; faces (F, 3). Mean over vertices (and batch) of the
    squared distance of the unit normals (dimensionless, in [0, 4]).
    """
    return vertex_loss(vertex_normals(pred, faces), vertex_normals(gt, faces))


def triangle_frames(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Sumner–Popović frame of every triangle: columns [v1 - v0, v2 - v0, n / sqrt(|n|)].

    n = (v1 - v0) × (v2 - v0); the third column is the offset of the "fourth vertex" that makes the
    triangle a tetrahedron, scaled so that it has the units of an edge.
    verts (..., V, 3), faces (F, 3) -> (..., F, 3, 3).
    """
    v0, v1, v2 = (verts[..., faces[:, i], :] for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    n = torch.linalg.cross(e1, e2, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(_EPS).sqrt()
    return torch.stack([e1, e2, n], dim=-1)


def deformation_gradients(verts: torch.Tensor, rest: torch.Tensor,
                          faces: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-face deformation Jacobians J = V_def · V_rest⁻¹ (Sumner & Popović 2004).

    Args:
        verts: (..., V, 3) deformed vertices.
        rest: (V, 3) rest (neutral) vertices.
        faces: (F, 3) int64.
    Returns:
        J (..., F, 3, 3), and valid (F,) bool: faces whose rest area exceeds 1e-6 of the mean
        rest face area (J is set to 0 on the others, whose rest frame is singular).
    """
    frames = triangle_frames(rest, faces)
    area2 = torch.linalg.cross(frames[..., 0], frames[..., 1], dim=-1).norm(dim=-1)
    valid = area2 > 1e-6 * area2.mean()
    eye = torch.eye(3, dtype=rest.dtype, device=rest.device)
    inv = torch.linalg.inv(torch.where(valid[:, None, None], frames, eye))
    return triangle_frames(verts, faces) @ (inv * valid[:, None, None]), valid


def jacobian_loss(pred: torch.Tensor, gt: torch.Tensor, rest: torch.Tensor,
                  faces: torch.Tensor) -> torch.Tensor:
    """L_g = ||g - g_GT||² (eq. 3) between per-face deformation Jacobians (rest -> deformed).

    pred, gt: (..., V, 3) deformed vertices; rest (V, 3) the neutral mesh; faces (F, 3).
    Squared Frobenius norm of J_pred - J_GT, mean over non-degenerate faces (and batch);
    dimensionless, invariant to translating pred or gt, zero when pred = gt + t.
    """
    j_pred, valid = deformation_gradients(pred, rest, faces)
    j_gt, _ = deformation_gradients(gt, rest, faces)
    per_face = (j_pred - j_gt).pow(2).sum((-2, -1))
    return per_face[..., valid].mean()


def decoder_loss(pred: torch.Tensor, gt: torch.Tensor, rest: torch.Tensor, faces: torch.Tensor,
                 lambda_v: float = 10.0, lambda_n: float = 1.0, lambda_g: float = 1.0
                 ) -> dict[str, torch.Tensor]:
    """L_dec = λ_v L_v + λ_n L_n + λ_g L_g (eq. 3; the paper's weights 10, 1, 1).

    pred, gt: (..., V, 3) predicted and GT deformed meshes (rest + Δv), rest (V, 3), faces (F, 3)
    (decode every vertex of the faces given; a vertex subset needs its faces re-indexed to it).
    Returns {"L_v", "L_n", "L_g", "L_dec"} scalars.
    """
    parts = {"L_v": vertex_loss(pred, gt), "L_n": normal_loss(pred, gt, faces),
             "L_g": jacobian_loss(pred, gt, rest, faces)}
    parts["L_dec"] = lambda_v * parts["L_v"] + lambda_n * parts["L_n"] + lambda_g * parts["L_g"]
    return parts


def supervised_code_loss(z: torch.Tensor, z_gt: torch.Tensor) -> torch.Tensor:
    """||z[:K] - z_GT||² + ||z[K:]||² (eq. 4): the first K dims follow the K true coefficients and
    the extra dims go to zero. z (..., D), z_gt (..., K) with K <= D. Squared norms summed over the
    D dims, as the equation writes them, then averaged over the batch. (A mean over the dims would
    weaken the code supervision D times against L_dec.)
    """
    k = z_gt.shape[-1]
    if k > z.shape[-1]:
        raise ValueError(f"{k} true coefficients do not fit a {z.shape[-1]}-dim code")
    return (z[..., :k] - z_gt).pow(2).sum(-1).add(z[..., k:].pow(2).sum(-1)).mean()


def identity_loss(z_id: torch.Tensor, identity_gt: torch.Tensor) -> torch.Tensor:
    """L_ID (eq. 4): z_id (..., 128) vs the J identity coefficients (..., J); summed over dims."""
    return supervised_code_loss(z_id, identity_gt)


def expression_loss(z_ge: torch.Tensor, weights_gt: torch.Tensor) -> torch.Tensor:
    """L_Exp (eq. 4): z_ge (..., 128) vs the 53 true FACS weights (..., 53); summed over dims."""
    return supervised_code_loss(z_ge, weights_gt)


def blend(weights: torch.Tensor, basis: torch.Tensor) -> torch.Tensor:
    """Blendshape displacement w · B: weights (..., K), basis (K, V, 3) -> (..., V, 3)."""
    return torch.einsum("...k,kvc->...vc", weights, basis)


def blendshape_projection_loss(z_ge: torch.Tensor, weights_gt: torch.Tensor,
                               basis: torch.Tensor) -> torch.Tensor:
    """L_BP = ||z_GE[:53] · B - w_GT · B||² (eq. 7), trains the expression encoder.

    z_ge (..., 128) predicted codes, weights_gt (..., 53) true weights, basis (53, V, 3) the
    source rig's blendshape deltas. Squared distance, mean over vertices (and batch), units².
    """
    k = basis.shape[0]
    return vertex_loss(blend(z_ge[..., :k] - weights_gt, basis), torch.zeros_like(basis[0]))


def blendshape_reconstruction_loss(model, feat: torch.Tensor, c: torch.Tensor, codes,
                                   z_ge: torch.Tensor, basis: torch.Tensor,
                                   rows: torch.Tensor | None = None) -> torch.Tensor:
    """L_BR = ||sg(z_GE[:53]) · B - D(Ψ(sg(z_GE), z_Skin))||² (eq. 8), trains the decoder.

    The stop-gradient is applied here, so the expression encoder gets no gradient from L_BR; the
    decoder, skinning block and target codes do.

    Args:
        model: an ``NFSModel``.
        feat, c, codes: the mesh the rig ``basis`` lives on: features (V, 6), image code, and its
            ``model.encode_target`` codes.
        z_ge: (code_dim,) or (S, code_dim) predicted expression codes.
        basis: (53, V, 3) blendshape deltas of that mesh.
        rows: (n,) int64 vertices to decode, or None for all.
    Returns:
        Squared distance, mean over decoded vertices (and the S codes), units².
    """
    z_sg = z_ge.detach().reshape(-1, z_ge.shape[-1])
    sub = basis if rows is None else basis[:, rows]
    dv = model.decode_target(feat, c, codes, z_sg, rows)                            # (S, n, 3)
    return vertex_loss(dv, blend(z_sg[:, :basis.shape[0]], sub))


def rig_loss(model, feat: torch.Tensor, c: torch.Tensor, codes, basis: torch.Tensor,
             rows: torch.Tensor | None = None, shapes: torch.Tensor | None = None,
             relative: float = 0.0) -> torch.Tensor:
    """L_rig = mean_k ||D(Ψ([e_k, 0], z_Skin)) - B_k||²: the decoder driven by one FACS weight at 1
    and every other dim of z_GE at 0 draws that shape of the target's rig (beyond the paper: L_BR,
    eq. 8, with one-hot codes instead of the encoder's). It makes the first 53 dims of the code
    mean the FACS shapes by themselves, which is what driving from FACS weights, the baked rig and
    exporting it read. Trains the decoder, skinning block and target codes.

    Args:
        model: an ``NFSModel``.
        feat, c, codes: the target: features (V, 6), image code, ``model.encode_target`` codes.
        basis: (53, V, 3) blendshape deltas of that mesh, in the units of ``feat``'s positions.
        rows: (n,) int64 vertices to decode, or None for all.
        shapes: (K,) int64 shape indices to decode, or None for all 53.
        relative: τ > 0 weighs shape k's squared error by m̄ / (m_k + τ m̄), m_k its mean squared
            displacement and m̄ the mean of m_k over the K shapes (beyond the paper): each shape's
            error relative to its own size, so the small shapes (eye looks, brows) count as much
            as jawOpen, up to 1/τ times the weight of an average one. 0: plain squared error.
    Returns:
        Squared distance, mean over the K shapes and the decoded vertices, units².
    """
    from .model import weights_to_code

    k = torch.arange(basis.shape[0], device=basis.device) if shapes is None else shapes
    z = weights_to_code(F.one_hot(k, basis.shape[0]).to(basis.dtype), model.cfg.code_dim)
    sub = basis[k] if rows is None else basis[k][:, rows]
    pred = model.decode_target(feat, c, codes, z, rows)
    if relative <= 0.0:
        return vertex_loss(pred, sub)
    size = sub.pow(2).sum(-1).mean(-1)                              # m_k (K,)
    mean = size.mean()
    err = (pred - sub).pow(2).sum(-1).mean(-1)                      # (K,)
    return (err * mean / (size + relative * mean + 1e-12)).mean()


def solve_loss(model, feat: torch.Tensor, c: torch.Tensor, codes, basis: torch.Tensor,
               weights: torch.Tensor, rows: torch.Tensor | None = None,
               ridge: float = 0.01) -> torch.Tensor:
    """L_solve = mean |ŵ − w|: the weights that inverse rigging on the decoder's baked rig would
    return for frames of the target's true rig (beyond the paper). A (53, 3n) holds the decoder's
    one-hot shapes D(Ψ([e_k, 0])) on the decoded vertices, x = w B the true frames there, and
    ŵ = (A Aᵀ + λ m̄ I)⁻¹ A x their ridge least-squares weights (m̄ the mean diagonal of A Aᵀ):
    invert's fit without its bounds and priors. Where L_rig weighs every error of the baked shapes
    alike, this weighs those that move the fitted weights: errors of one shape towards another.

    Args:
        model, feat, c, codes: the target, as for ``rig_loss``.
        basis: (53, V, 3) the target's true blendshape deltas (units of ``feat``'s positions).
        weights: (S, 53) the frames' true FACS weights (0 for shapes the rig lacks).
        rows: (n,) int64 vertices to decode, or None for all.
        ridge: λ, relative to m̄.
    Returns:
        The mean absolute weight error over the S frames and 53 weights (weight units).
    """
    from .model import weights_to_code

    n = basis.shape[0]
    z = weights_to_code(torch.eye(n, dtype=basis.dtype, device=basis.device), model.cfg.code_dim)
    a = model.decode_target(feat, c, codes, z, rows).reshape(n, -1)                 # (53, 3n)
    sub = basis if rows is None else basis[:, rows]
    x = weights @ sub.reshape(n, -1)                                                # (S, 3n)
    gram = a @ a.T
    lam = ridge * torch.diagonal(gram).mean().detach() + 1e-12
    w_hat = torch.linalg.solve(gram + lam * torch.eye(n, dtype=a.dtype, device=a.device), a @ x.T).T
    return (w_hat - weights).abs().mean()


#: Canonical units that a skinning descriptor channel's range (0, 1) spans in L_corr: the base
#: bust in its face frame spans x ±23, y −32..15, z ±10 (the head alone ±8), all well inside it.
TEMPLATE_SPAN = 72.0


def descriptor_template(descriptor: torch.Tensor) -> torch.Tensor:
    """The template position that descriptor channels (V, 3) in (0, 1) stand for: (V, 3) canonical
    units, (descriptor − 0.5) · TEMPLATE_SPAN."""
    return (descriptor - 0.5) * TEMPLATE_SPAN


def correspondence_loss(descriptor: torch.Tensor, template: torch.Tensor) -> torch.Tensor:
    """L_corr (beyond the paper): the first three skinning descriptor channels (V, 3) in (0, 1) read
    as a position on the template head (``descriptor_template``) against each vertex's true
    template position (V, 3) (``training_data.template_positions``): squared distance in canonical
    units², mean over vertices. It makes the descriptor a dense correspondence to one head, so the
    decoder's M(x) can draw each FACS shape where it belongs on a face it has not seen."""
    return (descriptor_template(descriptor) - template).pow(2).sum(-1).mean()


def segmentation_nll(z_skin: torch.Tensor, labels: torch.Tensor) -> torch.Tensor:
    """L_nll (eq. 2): binary cross-entropy of z_Skin against one-hot segment labels.

    z_skin (V, L) in (0, 1); labels (V,) int64 in [0, L). Sum over the L segments, mean over
    vertices (the 1/N of eq. 2).
    """
    y = F.one_hot(labels, z_skin.shape[-1]).to(z_skin.dtype)
    return F.binary_cross_entropy(z_skin, y, reduction="sum") / z_skin.shape[0]


def code_range_loss(z: torch.Tensor) -> torch.Tensor:
    """L_reg (eq. 5, from NFR): -z below 0, z - 1 above 1, 0 inside [0, 1]; mean over all entries.

    z (..., D) codes of samples without rig labels (the caller picks which dims to constrain).
    """
    return (F.relu(-z) + F.relu(z - 1.0)).mean()

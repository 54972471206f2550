"""FACS blendshape names: the 53 ICT-FaceKit expressions and the ARKit 52 mapping.

The ICT order (alphabetical, as in ICT-FaceKit ``vertex_indices.json``) is the order of the first
53 dimensions of the global expression code z_GE and of every weight array in this project.
ARKit uses camelCase with ``Left``/``Right``; ``browInnerUp`` and ``cheekPuff`` drive both ICT
halves, ``tongueOut`` has no ICT shape.
"""
import numpy as np

FACS_NAMES = (
    "browDown_L", "browDown_R", "browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R",
    "cheekPuff_L", "cheekPuff_R", "cheekSquint_L", "cheekSquint_R", "eyeBlink_L", "eyeBlink_R",
    "eyeLookDown_L", "eyeLookDown_R", "eyeLookIn_L", "eyeLookIn_R", "eyeLookOut_L", "eyeLookOut_R",
    "eyeLookUp_L", "eyeLookUp_R", "eyeSquint_L", "eyeSquint_R", "eyeWide_L", "eyeWide_R",
    "jawForward", "jawLeft", "jawOpen", "jawRight", "mouthClose", "mouthDimple_L", "mouthDimple_R",
    "mouthFrown_L", "mouthFrown_R", "mouthFunnel", "mouthLeft", "mouthLowerDown_L",
    "mouthLowerDown_R", "mouthPress_L", "mouthPress_R", "mouthPucker", "mouthRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper", "mouthSmile_L",
    "mouthSmile_R", "mouthStretch_L", "mouthStretch_R", "mouthUpperUp_L", "mouthUpperUp_R",
    "noseSneer_L", "noseSneer_R",
)
N_FACS = len(FACS_NAMES)  # 53
FACS_INDEX = {name: i for i, name in enumerate(FACS_NAMES)}

# ARKit names in Apple's ARFaceAnchor.BlendShapeLocation order (52).
ARKIT_NAMES = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight",
    "eyeLookOutRight", "eyeLookUpRight", "eyeSquintRight", "eyeWideRight", "jawForward", "jawLeft",
    "jawRight", "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft",
    "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight", "mouthRollLower", "mouthRollUpper",
    "mouthShrugLower", "mouthShrugUpper", "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft",
    "mouthLowerDownRight", "mouthUpperUpLeft", "mouthUpperUpRight", "browDownLeft", "browDownRight",
    "browInnerUp", "browOuterUpLeft", "browOuterUpRight", "cheekPuff", "cheekSquintLeft",
    "cheekSquintRight", "noseSneerLeft", "noseSneerRight", "tongueOut",
)


def arkit_to_ict(name: str) -> tuple[str, ...]:
    """ICT names fed by one ARKit name: () for tongueOut, two for browInnerUp/cheekPuff."""
    if name in ("browInnerUp", "cheekPuff"):
        return (name + "_L", name + "_R")
    if name == "tongueOut":
        return ()
    for side, suffix in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side) and name[: -len(side)] + suffix in FACS_INDEX:
            return (name[: -len(side)] + suffix,)
    if name in FACS_INDEX:
        return (name,)
    raise KeyError(f"not an ARKit blendshape name: {name!r}")


def ict_to_arkit(name: str) -> str:
    """The ARKit name that carries one ICT name (browInnerUp_L and _R both give browInnerUp)."""
    if name not in FACS_INDEX:
        raise KeyError(f"not an ICT FACS name: {name!r}")
    base, _, side = name.rpartition("_")
    if base in ("browInnerUp", "cheekPuff"):
        return base
    if side in ("L", "R") and base:
        return base + ("Left" if side == "L" else "Right")
    return name


def left_weight(x, centre: float, half_band: float) -> np.ndarray:
    """(V,) float32 in [0,1]: 1 on the character's left (x > centre + half_band), 0 on the right
    (x < centre - half_band), a smoothstep between; x (V,) the vertices' x coordinates."""
    t = np.clip(0.5 + 0.5 * (np.asarray(x, np.float64) - centre) / half_band, 0.0, 1.0)
    return (t * t * (3.0 - 2.0 * t)).astype(np.float32)


def split_to_ict(shapes, left: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shapes as (ICT slot indices, delta (V,3)) pairs -> (deltas (53,V,3) float32 in ICT order,
    present (53,) bool). A shape with one slot fills it; one with two (ARKit ``browInnerUp``,
    ``cheekPuff``: the ``_L`` slot first) is split by ``left`` (V,) (:func:`left_weight`) into
    delta·left and delta·(1 - left); one with none (``tongueOut``) is left out."""
    left = np.asarray(left, np.float32)[:, None]
    deltas = np.zeros((N_FACS, len(left), 3), np.float32)
    present = np.zeros(N_FACS, bool)
    for idx, d in shapes:
        d = np.asarray(d, np.float32)
        if len(idx) == 2:
            deltas[idx[0]], deltas[idx[1]] = d * left, d * (1.0 - left)
        elif len(idx) == 1:
            deltas[idx[0]] = d
        present[list(idx)] = True
    return deltas, present

"""Tuning study of refine's least-squares priors (``retarget.api.Retargeter.REFINE_*``) on a tuning
set apart from the eval's test set: configs/eval/study.yaml with seed 100 (other test-split
identities and weights than the eval's seed 0).

A variant sets the pull of the fitted weights towards the encoder's for transfer
(``REFINE_PRIOR``) and for invert (``REFINE_PRIOR_INVERT``), the ridge of the free dims
(``REFINE_FREE_PRIOR``) and the L1 pull of the inverted weights towards 0
(``REFINE_SPARSITY_INVERT``), then runs the refine mode of ``retarget eval`` on the suites.
Variants named "invert ..." change only inversion and run only its suites (``INVERSE_SUITES``);
``TRANSFER_VARIANTS`` (not run by default) the L1 pull of transfer's fitted weights;
``JOINT_VARIANTS`` (not run by default) the joint fit of weights and free dims.

    OMP_NUM_THREADS=1 python docs/results/stage7/refine_priors.py CHECKPOINT OUT.json [VARIANT ...]
"""
import json
import sys

from retarget.api import Retargeter
from retarget.evaluate import DoNothingMethod, Evaluation, NetworkMethod, load_eval_config

VARIANTS = {  # name: (REFINE_PRIOR, REFINE_PRIOR_INVERT, REFINE_FREE_PRIOR, REFINE_SPARSITY_INVERT)
    "stage 6 priors": (1e-3, 1.0, 1e-3, 0.0),
    "free 1e-5": (1e-3, 1.0, 1e-5, 0.0),
    "prior 1e-5, free 1e-5": (1e-5, 1.0, 1e-5, 0.0),
    **{f"invert prior {p}, sparsity {mu}": (1e-3, p, 1e-3, mu)
       for p in (1.0, 0.3, 0.1, 0.03, 0.01) for mu in (0.0, 0.02, 0.05) if (p, mu) != (1.0, 0.0)},
    "invert sparsity 0.1": (1e-3, 1.0, 1e-3, 0.1),
}
#: transfer with an L1 pull of its fitted weights towards 0 (``REFINE_SPARSITY``), on the
#: transfer suites (``TRANSFER_SUITES``): name -> REFINE_SPARSITY, the rest as the bundled
TRANSFER_VARIANTS = {f"transfer sparsity {mu}": mu for mu in (0.0, 0.002, 0.01, 0.05)}
#: weights and free dims fitted together (``REFINE_JOINT``, ``REFINE_JOINT_INVERT``; the free-dims
#: ridge ``REFINE_FREE_PRIOR``) beside the bundled settings, on the transfer and inverse suites
JOINT_VARIANTS = {
    "bundled": {},
    "joint": {"REFINE_JOINT": True, "REFINE_JOINT_INVERT": True},
    "joint, free 1e-2": {"REFINE_JOINT": True, "REFINE_JOINT_INVERT": True, "REFINE_FREE_PRIOR": 1e-2},
    "joint, free 1e-1": {"REFINE_JOINT": True, "REFINE_JOINT_INVERT": True, "REFINE_FREE_PRIOR": 1e-1},
    "joint, free 1e-4": {"REFINE_JOINT": True, "REFINE_FREE_PRIOR": 1e-4},
    "joint, free 1e-5": {"REFINE_JOINT": True, "REFINE_FREE_PRIOR": 1e-5},
    "joint, prior 1e-2": {"REFINE_JOINT": True, "REFINE_PRIOR": 1e-2},
    "joint, prior 1e-4": {"REFINE_JOINT": True, "REFINE_PRIOR": 1e-4},
}
TRANSFER_SUITES = ("self", "cross_identity", "head_self", "head_cross_identity", "head_cross_topology")
SUITES = ("self", "inverse", "real_rig", "head_self", "head_cross_identity", "head_inverse")
INVERSE_SUITES = ("inverse", "real_rig", "head_inverse")


def summary(suite: str, e: dict) -> str:
    if suite == "real_rig":
        e = e["sampled"]
        return (f"real->real {e['real_to_real']['mse_mm2']:.4g}, invert rig "
                f"{e['invert']['rig_mse_mm2']:.4g} / MAE {e['invert']['weight_mae']:.4f}")
    return f"seg {e['seg_mse_mm2']:.4g}" + (f" / MAE {e['weight_mae']:.4f}" if "weight_mae" in e else "")


def variant(name: str) -> tuple[dict, tuple]:
    """The Retargeter attributes and the suites of a variant."""
    if name in JOINT_VARIANTS:
        return JOINT_VARIANTS[name], tuple(dict.fromkeys(TRANSFER_SUITES + INVERSE_SUITES))
    if name in TRANSFER_VARIANTS:
        return {"REFINE_SPARSITY": TRANSFER_VARIANTS[name]}, TRANSFER_SUITES
    keys = ("REFINE_PRIOR", "REFINE_PRIOR_INVERT", "REFINE_FREE_PRIOR", "REFINE_SPARSITY_INVERT")
    return dict(zip(keys, VARIANTS[name])), INVERSE_SUITES if name.startswith("invert") else SUITES


def main(checkpoint: str, out: str, names=None) -> None:
    cfg = load_eval_config("configs/eval/study.yaml")
    cfg["seed"] = 100
    results, data = {}, None
    for name in names or VARIANTS:
        r = Retargeter.load(checkpoint)
        attrs, suites = variant(name)
        for k, v in attrs.items():
            setattr(r, k, v)
        missing = [s for s in suites if "do nothing" not in results.get(s, {})]
        methods = [NetworkMethod(name, r, "refine")]
        ev = Evaluation(cfg, methods, progress=False, data=data)
        data = ev.data
        for s, v in ev.run(suites)["suites"].items():
            results.setdefault(s, {}).update(v["methods"])
        if missing:
            for s, v in Evaluation(cfg, [DoNothingMethod()], progress=False, data=data).run(missing)["suites"].items():
                results[s].update(v["methods"])
        print(name, flush=True)
        for s in suites:
            print(f"  {s}: {summary(s, results[s][name])}", flush=True)
        with open(out, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3:] or None)

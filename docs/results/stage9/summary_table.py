"""The table of docs/RESULTS.md's Summary from two eval.json files of the default eval config:
the bundled model's (methods "NAME (no neutral)", "(neutral)", "(neutral + refine)") and the
previous bundled model's, with the do-nothing and closest-point rows; and, where the new eval has
them, the rows "NAME (estimated neutral + refine)" (a take without its neutral mesh,
``--estimate-neutral --refine``) as a column after "no neutral". Segment-averaged MSE in mm²
(the ARKit rig: plain MSE), each with its ratio to doing nothing; inverse suites also the weight MAE.

    python docs/results/stage9/summary_table.py NEW_EVAL_JSON NEW_NAME OLD_EVAL_JSON OLD_NAME [OLD_LABEL]
"""
import json
import sys

ROWS = (  # (label, suite, kind)
    ("procedural heads: self-retargeting", "self", "seg"),
    ("procedural: cross-identity", "cross_identity", "seg"),
    ("procedural: cross-topology", "cross_topology", "seg"),
    ("procedural: inverse rigging, rig MSE / weight MAE", "inverse", "inverse"),
    ("procedural: driving from FACS weights", "animate", "animate"),
    ("realistic MakeHuman heads: self-retargeting", "head_self", "seg"),
    ("realistic: cross-identity", "head_cross_identity", "seg"),
    ("realistic: cross-topology", "head_cross_topology", "seg"),
    ("realistic: cross-crop (bust → head, face → bust)", "head_cross_crop", "seg"),
    ("realistic: inverse rigging, rig MSE / weight MAE", "head_inverse", "inverse"),
    ("realistic: driving from FACS weights", "head_animate", "animate"),
    ("the artist's ARKit rig (makehuman_arkit.npz): real → real, plain MSE", "real_rig", "real_to_real"),
    ("ARKit rig: inversion, rig MSE / weight MAE", "real_rig", "invert"),
    ("ARKit rig: driving from its true weights", "real_rig", "real_animate"),
    ("ARKit rig: unmoved, its neutral onto itself (the floor)", "real_rig", "unmoved"),
)
MODES = ("no neutral", "neutral", "neutral + refine")
ESTIMATE = "estimated neutral + refine"


def g(x: float) -> str:
    return "0" if abs(x) < 1e-6 else f"{x:.4g}"   # exact (closest point on one mesh or rig)


def value(suites: dict, suite: str, method: str, kind: str):
    """(error, weight MAE or None) of ``method`` in ``suite``; None when absent."""
    m = suites.get(suite, {}).get("methods", {}).get(method)
    if m is None:
        return None
    if kind in ("seg", "animate"):
        return m["seg_mse_mm2"], None
    if kind == "inverse":
        return m["seg_mse_mm2"], m["weight_mae"]
    e = m["sampled"]
    key = {"real_to_real": "real_to_real", "invert": "invert", "real_animate": "animate"}.get(kind, "unmoved")
    if key not in e:
        return None
    if kind == "real_to_real":
        return e["real_to_real"]["mse_mm2"], None
    if kind == "invert":
        return e["invert"]["rig_mse_mm2"], e["invert"]["weight_mae"]
    return e[key]["mse_mm2"], None


def cell(v, nothing) -> str:
    if v is None:
        return "—"
    err, mae = v
    ratio = f" ({err / nothing[0]:.2f}×)" if nothing and nothing[0] > 0 and err > 1e-6 else ""
    return g(err) + ratio + (f" / {mae:.3f}" if mae is not None else "")


def main(new_path, new, old_path, old, old_label=None) -> None:
    a = json.loads(open(new_path).read())["suites"]
    b = json.loads(open(old_path).read())["suites"]
    old_label = old_label or old
    modes = list(MODES)
    if any(f"{new} ({ESTIMATE})" in res.get("methods", {}) for res in a.values()):
        modes.insert(1, ESTIMATE)
    print("| suite | do nothing | closest point | " + " | ".join(f"bundled, {m}" for m in modes)
          + f" | {old_label}, no neutral | {old_label}, neutral + refine |")
    print("| --- |" + " ---: |" * (len(modes) + 4))
    for label, suite, kind in ROWS:
        nothing = value(a, suite, "do nothing", kind)
        row = [label, (g(nothing[0]) + (f" / {nothing[1]:.4g}" if nothing[1] is not None else ""))
               if nothing else "—", cell(value(a, suite, "closest point", kind), nothing)]
        same = kind in ("animate", "real_animate")   # no source mesh: every mode the same
        for i, mode in enumerate(modes):
            row.append("(the same)" if same and i else cell(value(a, suite, f"{new} ({mode})", kind), nothing))
        for mode in ("no neutral", "neutral + refine"):
            row.append("(the same)" if same and mode != "no neutral"
                       else cell(value(b, suite, f"{old} ({mode})", kind), value(b, suite, "do nothing", kind)))
        if kind == "unmoved":   # an absolute floor: doing nothing is exact there
            row = row[:1] + [c.split(" (")[0] for c in row[1:]]
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main(*sys.argv[1:])

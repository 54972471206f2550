"""How much motion the stabiliser finds where there is none: the eval's test frames (which do not
move) fitted against their neutral on every vertex, and on the REST_SHARE least-moved vertices of
the source's baked rig for several shares (docs/RESULTS.md, "Frames that move as a whole").
Per suite and kind of source: the largest and the 90th-percentile displacement of a vertex by the
fitted motion, relative to the neutral's bounding-box diagonal (0 would be exact).

    python docs/results/stabilise/rest_share.py --out docs/results/stabilise/rest_share.md
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

SHARES = (0.3, 0.1, 0.05)
SUITES = ("inverse", "cross_topology", "head_inverse", "head_cross_crop")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    from retarget import stabilise
    from retarget.api import Retargeter
    from retarget.evaluate import EvalData, load_eval_config
    from retarget.mesh import Mesh

    data = EvalData(load_eval_config(None))
    r = Retargeter.load()
    columns = ["every vertex"] + [f"{s:g} of the rig's" for s in SHARES]
    found: dict = {}
    for suite in SUITES:
        for case in data.cases(suite):
            group = f"{suite}: {case.label.split(':')[0]}" if ":" in case.label else suite
            neutral = np.asarray(case.source.neutral, np.float64)
            deltas = r.source_rig(Mesh(neutral, case.source.faces)).baked.deltas
            rests = [np.arange(len(neutral))]
            for share in SHARES:
                stabilise.REST_SHARE = share
                rests.append(stabilise.rest_vertices(deltas))
            for col, rest in zip(columns, rests):
                found.setdefault((group, col), []).extend(
                    stabilise.rigid_fit(f, neutral, rest).moved for f in case.source_frames)
        print(suite, "done", flush=True)
    lines = ["Largest / 90th-percentile vertex displacement of the fitted motion on unmoved frames, "
             "relative to the head's diagonal.", "",
             "| suite: source | " + " | ".join(columns) + " |", "| --- |" + " ---: |" * len(columns)]
    for group in dict.fromkeys(g for g, _ in found):
        cells = [found[(group, c)] for c in columns]
        lines.append(f"| {group} | " + " | ".join(f"{max(v):.1e} / {np.quantile(v, 0.9):.1e}"
                                                  for v in cells) + " |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).write_text(text)


if __name__ == "__main__":
    main()

"""Whether two ``retarget eval`` outputs hold the same numbers: every number of the first
eval.json's suites compared with the second's (timings left out); prints how many were compared,
how many differ, and how many differ by more than 1e-6 relative (docs/RESULTS.md, "Heads that do
not face +z").

    python docs/results/orientation/same_numbers.py docs/results/eval/eval.json runs/upright_a/eval.json
"""
from __future__ import annotations

import json
import sys


def differences(a, b, path=()):
    """Yield (path, a, b) for every number of ``a`` that differs from ``b`` at the same place."""
    if isinstance(a, dict):
        for k in a:
            if k in b and k != "seconds":
                yield from differences(a[k], b[k], path + (k,))
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            yield from differences(x, y, path + (str(i),))
    elif isinstance(a, (int, float)) and not isinstance(a, bool) and isinstance(b, (int, float)):
        differences.compared += 1
        if a != b:
            yield path, a, b


def main(reference: str, other: str) -> None:
    differences.compared = 0
    diff = list(differences(json.load(open(other))["suites"], json.load(open(reference))["suites"]))
    large = [d for d in diff if abs(d[1] - d[2]) > 1e-6 * max(abs(d[1]), abs(d[2]))]
    print(f"{other}: {differences.compared} numbers compared with {reference}; {len(diff)} differ, "
          f"{len(large)} by more than 1e-6 relative")
    for d in large[:10]:
        print("  ", " / ".join(d[0]), d[2], "->", d[1])


if __name__ == "__main__":
    main(*sys.argv[1:3])

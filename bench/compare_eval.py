"""Compare two face-reid-eval JSON files, wall-clock timing keys aside: exit 0 when identical, else list the
differing paths (a refactoring that changes no behaviour must leave the evaluation identical)."""

from __future__ import annotations

import json
import sys
from typing import Any

TIMING = ("run_time_s", "total_time_s")


def _timing(key: str) -> bool:
    return key in TIMING or key.endswith("_time") or key.endswith("_time_s") or "timing" in key


def differences(a: Any, b: Any, path: str = "") -> list[str]:
    """Paths where ``a`` and ``b`` differ (timing keys skipped)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for key in sorted(set(a) | set(b)):
            if _timing(key):
                continue
            if key not in a or key not in b:
                out.append(f"{path}/{key}: only in {'second' if key not in a else 'first'}")
            else:
                out.extend(differences(a[key], b[key], f"{path}/{key}"))
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def main(argv: list[str]) -> int:
    with open(argv[0]) as fa, open(argv[1]) as fb:
        diff = differences(json.load(fa), json.load(fb))
    for line in diff[:50]:
        print(line)
    print("identical" if not diff else f"{len(diff)} difference(s)")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

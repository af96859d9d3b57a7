#!/usr/bin/env python3
"""Compares two trace results (drillctl trace ... -o F.json): is every codimension-2 point of the
first found in the second with the same kind, within a tolerance in the traced parameters?

  python3 bench/compare_traces.py BEFORE.json AFTER.json [--tol 1e-8] [--params omega,a]

Prints the counts of both results (curves, vertices, codimension-2 entries by kind), the points of
BEFORE missing from AFTER (no point of that kind within tol in every traced parameter) and those
of AFTER new against BEFORE, and the curves by (kind, start kind) whose counts differ. Exit status
0 when no point of BEFORE is missing, 1 otherwise.
"""
import argparse
import bisect
import collections
import json
import sys


def load(path):
    with open(path) as f:
        d = json.load(f)
    if "curves" not in d and "result" in d:
        d = d["result"]
    return d


def traced_params(result):
    """The two parameters that vary over the codimension-2 points (omega, a for the box)."""
    pts = result.get("codim2Points", [])
    if not pts:
        return []
    names = list(pts[0]["params"].keys())
    # The two of widest spread (the fixed ones differ only by rounding, ~1e-17).
    spread = {n: max(p["params"][n] for p in pts) - min(p["params"][n] for p in pts) for n in names}
    return sorted(names, key=lambda n: -spread[n])[:2]


def index_points(points, params):
    """Points by kind, sorted by the first parameter, for window lookups."""
    by_kind = collections.defaultdict(list)
    for i, p in enumerate(points):
        by_kind[p["kind"]].append((p["params"][params[0]], i))
    for v in by_kind.values():
        v.sort()
    return by_kind


def unmatched(src, dst, params, tol):
    """Points of src with no point of dst of the same kind within tol in every parameter."""
    index = index_points(dst, params)
    missing = []
    for p in src:
        cands = index.get(p["kind"], [])
        x = p["params"][params[0]]
        lo = bisect.bisect_left(cands, (x - tol, -1))
        found = False
        for xv, j in cands[lo:]:
            if xv > x + tol:
                break
            q = dst[j]
            if all(abs(q["params"][n] - p["params"][n]) <= tol for n in params):
                found = True
                break
        if not found:
            missing.append(p)
    return missing


def describe(result):
    curves = result.get("curves", [])
    pts = result.get("codim2Points", [])
    kinds = collections.Counter(p["kind"] for p in pts)
    return (f"{len(curves)} curves, {sum(len(c.get('points', [])) for c in curves)} vertices, "
            f"{len(pts)} codimension-2 entries ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--tol", type=float, default=1e-8, help="per-parameter tolerance (default 1e-8)")
    ap.add_argument("--params", default="", help="the traced parameters, e.g. omega,a (default: detected)")
    ap.add_argument("--show", type=int, default=20, help="how many missing / new points to list")
    args = ap.parse_args()
    before, after = load(args.before), load(args.after)
    params = args.params.split(",") if args.params else traced_params(before)
    print(f"before: {describe(before)}")
    print(f"after:  {describe(after)}")
    bp, ap_ = before.get("codim2Points", []), after.get("codim2Points", [])
    missing = unmatched(bp, ap_, params, args.tol)
    new = unmatched(ap_, bp, params, args.tol)
    print(f"codimension-2 points of before not in after (same kind, |d{'|, |d'.join(params)}| <= {args.tol:g}): "
          f"{len(missing)}; of after not in before: {len(new)}")
    for title, pts in (("missing", missing), ("new", new)):
        for p in pts[: args.show]:
            where = ", ".join(f"{n} = {p['params'][n]:.10g}" for n in params)
            print(f"  {title}: {p['kind']} at {where} (curve {p.get('curve')}, bracket {p.get('bracket', 0):.2g})")
    count = lambda r: collections.Counter((c["kind"], c.get("startKind", "")) for c in r.get("curves", []))
    cb, ca = count(before), count(after)
    for key in sorted(set(cb) | set(ca)):
        if cb[key] != ca[key]:
            print(f"  curves {key[0]} started from {key[1]}: {cb[key]} -> {ca[key]}")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())

"""`holoflow models list [--profile P]` | `holoflow models random DIR [--full] [--seed N]`: the real-model
engines' weights (holoflow/networks/manifest.py). Nothing here downloads."""
from __future__ import annotations

import json
from pathlib import Path

from holoflow.networks.manifest import apply_manifest, needs, write_random


def main(argv: list[str]) -> int:
    """`holoflow models list [--profile P]` | `holoflow models random DIR [--full] [--seed N]`."""
    import argparse
    import sys

    p = argparse.ArgumentParser(prog="holoflow models", description="the real-model engines' weights")
    sub = p.add_subparsers(dest="verb", required=True)
    ls = sub.add_parser("list", help="one line per model the profile's real engines load: present or not, "
                        "and how to get it")
    ls.add_argument("--profile", default="paper", help="profile (comma list allowed; default paper)")
    ls.add_argument("--pipeline", default="pipeline.yaml")
    ls.add_argument("--models", metavar="DIR", help="look in DIR's manifest.json first (as run --models)")
    ls.add_argument("--json", action="store_true")
    rnd = sub.add_parser("random", help="write random models of every real architecture + manifest.json")
    rnd.add_argument("folder", metavar="DIR")
    rnd.add_argument("--full", action="store_true", help="published sizes (GBs; for timing), not tiny ones")
    rnd.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.verb == "random":
        write_random(Path(args.folder), full=args.full, seed=args.seed,
                     progress=lambda m: print(m, file=sys.stderr))
        print(f"holoflow models: random {'full-size' if args.full else 'tiny'} models in {args.folder} "
              f"(noise images at the real compute cost); use: holoflow run --models {args.folder}")
        return 0
    from holoflow.flow.pipeline import find_pipeline, load, resolve

    pipe = load(find_pipeline(args.pipeline))
    resolved = resolve(pipe, args.profile)
    if args.models:
        apply_manifest(resolved, Path(args.models))
    found = needs(resolved)
    if args.json:
        print(json.dumps([n.__dict__ for n in found], indent=1))
        return 0
    if not found:
        print(f"holoflow models: profile '{args.profile}' uses no real-model engine")
        return 0
    for n in found:
        state = "present" if n.present else "MISSING"
        print(f"{n.stage + '.' + n.param:<24} {n.engine:<18} {state:<8} {n.model or '(none)'}")
        print(f"    {'at ' + n.detail if n.present else 'get: ' + n.detail}")
    missing = sum(not n.present for n in found)
    print(f"holoflow models: {len(found) - missing} of {len(found)} present"
          + ("; without weights: `holoflow models random DIR` then `holoflow run --models DIR` gives the "
             "real compute cost with noise images" if missing else ""))
    return 0

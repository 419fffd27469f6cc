"""`holoflow models list [--profile P]` | `holoflow models pull [--profile P | MODEL...]` |
`holoflow models random DIR [--full] [--only ROLE]...`: the real-model engines' weights
(holoflow/networks/manifest.py). Only `pull` downloads, into the user's Hugging Face cache."""

from __future__ import annotations

import json
from pathlib import Path

from holoflow.networks.manifest import PullError, apply_manifest, needs, pull, pull_targets, write_random


def main(argv: list[str]) -> int:
    """`holoflow models list|pull|random ...`."""
    import argparse
    import sys

    p = argparse.ArgumentParser(prog="holoflow models", description="the real-model engines' weights")
    sub = p.add_subparsers(dest="verb", required=True)
    ls = sub.add_parser(
        "list",
        help="one line per model the profile's real engines load (and each auto "
        "engine's optional network): present or not, licence, and how to get it",
    )
    ls.add_argument("--profile", help="profile (comma list allowed; default: the pipeline's default profile)")
    ls.add_argument("--pipeline", default="pipeline.yaml")
    ls.add_argument("--models", metavar="DIR", help="look in DIR's manifest.json first (as run --models)")
    ls.add_argument("--json", action="store_true")
    pl = sub.add_parser(
        "pull",
        help="download the weights a profile's engines need (or the MODELs named) into "
        "the user's Hugging Face cache (HF_HOME / HF_HUB_CACHE); resumable",
        description="Fetch model weights through huggingface_hub (progress shown; an interrupted "
        "download resumes). Without arguments: what the default profile uses (its auto depth "
        "network: Depth Anything V2 Small, Apache-2.0).",
    )
    pl.add_argument(
        "models",
        nargs="*",
        metavar="MODEL",
        help="a role (e.g. depth_anything, zoedepth) or an HF "
        "id, e.g. depth-anything/Depth-Anything-V2-Base-hf (CC-BY-NC-4.0)",
    )
    pl.add_argument("--profile", help="what this profile's engines load (comma list allowed)")
    pl.add_argument("--pipeline", default="pipeline.yaml")
    rnd = sub.add_parser(
        "random", help="write random models of every real architecture (or of --only ROLEs) + manifest.json"
    )
    rnd.add_argument("folder", metavar="DIR")
    rnd.add_argument(
        "--only", action="append", default=[], metavar="ROLE", help="only this role (repeatable; e.g. depth_anything)"
    )
    rnd.add_argument("--full", action="store_true", help="published sizes (GBs; for timing), not tiny ones")
    rnd.add_argument(
        "--depth-variant",
        choices=["small", "large"],
        default="small",
        help="Depth Anything at full size: V2 Small (24.8 M, the default model) or Large (335 M)",
    )
    rnd.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.verb == "random":
        write_random(
            Path(args.folder),
            full=args.full,
            seed=args.seed,
            roles=args.only or None,
            depth_variant=args.depth_variant,
            progress=lambda m: print(m, file=sys.stderr),
        )
        print(
            f"holoflow models: random {'full-size' if args.full else 'tiny'} models in {args.folder} "
            f"(noise images at the real compute cost); use: holoflow run --models {args.folder}"
        )
        return 0
    from holoflow.flow.pipeline import find_pipeline, load, resolve

    pipe = load(find_pipeline(args.pipeline))
    profile = args.profile or pipe.default_profile
    if args.verb == "pull":
        if args.models and args.profile:
            p.error("pull takes --profile P or MODEL names, not both")
        try:
            targets, skipped = pull_targets(args.models, None if args.models else resolve(pipe, profile))
            for line in skipped:
                print(line, file=sys.stderr)
            paths = pull(targets, progress=lambda m: print(m, file=sys.stderr))
        except (PullError, ValueError) as e:
            print(str(e).splitlines()[0], file=sys.stderr)
            return 1
        for path in paths:
            print(f"holoflow models: present at {path}")
        print(f"holoflow models: `holoflow models list --profile {profile}` shows what the runs will use")
        return 0
    resolved = resolve(pipe, profile)
    if args.models:
        apply_manifest(resolved, Path(args.models))
    found = needs(resolved, optional=True)
    if args.json:
        print(json.dumps([n.__dict__ for n in found], indent=1))
        return 0
    if not found:
        print(f"holoflow models: profile '{profile}' uses no real-model engine")
        return 0
    for n in found:
        state = "present" if n.present else ("absent" if n.optional else "MISSING")
        print(f"{n.stage + '.' + n.param:<24} {n.engine:<26} {state:<8} {n.model or '(none)'}")
        if n.about:
            print(f"    {n.about}")
        print(f"    {'at ' + n.detail if n.present else 'get: ' + n.detail}")
    missing = sum(not n.present and not n.optional for n in found)
    print(
        f"holoflow models: {sum(n.present for n in found)} of {len(found)} present"
        + (
            "; without weights: `holoflow models random DIR` then `holoflow run --models DIR` gives the "
            "real compute cost with noise images"
            if missing
            else ""
        )
    )
    return 0

"""`holoflow gc [--yes]`: delete what the latest and pinned runs do not need (a dry run unless --yes)."""

from __future__ import annotations

import sys

from holoflow.commands.options import common, load, parser


def main(argv: list[str]) -> int:
    p = parser("gc")
    common(p, resolve_opts=False)
    p.add_argument("--yes", action="store_true", help="really delete")
    args = p.parse_args(argv)
    _, store = load(args)
    if not (store.root / "objects").is_dir():
        print(f"holoflow gc: {store.root} holds no store yet; nothing to do")
        return 0
    if args.yes:
        store.lock(None, "gc", lambda m: print(f"holoflow: {m}", file=sys.stderr))
    try:
        plan = store.gc_plan()
        mb = plan["bytes"] / 2**20
        verb = "deleted" if args.yes else "would delete"
        print(
            f"holoflow gc: {verb} {len(plan['runs'])} runs, {len(plan['keys'])} step records, "
            f"{len(plan['objects'])} objects ({mb:.1f} MiB); kept runs: {', '.join(plan['kept_runs']) or '-'}"
        )
        if args.yes:
            store.gc_apply(plan)
        elif plan["objects"] or plan["runs"]:
            print("holoflow gc: dry run; pass --yes to delete")
    finally:
        store.unlock()
    return 0

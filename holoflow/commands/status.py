"""`holoflow status [PROMPT]`: fresh / stale / missing per stage, and why (holoflow/flow/status.py)."""

from __future__ import annotations

import json
import sys

from holoflow.commands.options import common, load, options, parser


def main(argv: list[str]) -> int:
    p = parser("status")
    p.add_argument("prompt", nargs="?", help="text prompt (default: the last run's prompt)")
    common(p)
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    from holoflow.flow.context import Context
    from holoflow.flow.status import describe_ran, engine_note, status

    pipe, store = load(args)
    ctx = Context.build(pipe, store, options(args))
    from holoflow.networks.manifest import fill_auto

    fill_auto(ctx.resolved)  # as `run` does: an auto engine's network found in the cache is part of the key
    st = status(ctx)
    kinds = cpu_kinds(store, st)
    if args.json:
        print(json.dumps({"prompt": ctx.prompt, "profile": ctx.profile, "stages": st, "cpu_kinds": kinds}, indent=1))
        return 0
    width = max(len(n) for n in st)
    for name, s in st.items():
        why = "; ".join(s["reasons"]) or describe_ran(s.get("ran"))
        if s.get("engine"):
            why = f"{engine_note({'engine': s['engine']['ran'], 'why': s['engine']['why']})}; {why}"
        print(f"{name:<{width}}  {s['state']:<7}  {why}".rstrip())
    from holoflow.flow.executors.step_env import bytes_note

    if note := bytes_note(kinds):
        print(note, file=sys.stderr)  # a note, not a row of the table
    return 0


def cpu_kinds(store, st: dict) -> dict[str, list[str]]:
    """{CPU kind: [stage]} of the fresh steps' records ('' for records without one)."""
    from holoflow.flow.executors.step_env import cpu_kind

    kinds: dict[str, list[str]] = {}
    for name, s in st.items():
        rec = store.record(s["key"]) if s.get("key") and s["state"] == "fresh" else None
        if rec is not None:
            kinds.setdefault(cpu_kind(rec["provenance"].get("cpu")), []).append(name)
    return kinds

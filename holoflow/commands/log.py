"""`holoflow log STAGE`: print a stage's log from the latest run."""

from __future__ import annotations

import sys

from holoflow.commands import fail
from holoflow.commands.options import common, load, parser


def main(argv: list[str]) -> int:
    p = parser("log")
    p.add_argument("stage")
    common(p, resolve_opts=False)
    args = p.parse_args(argv)
    pipe, store = load(args)
    info = store.run_info(store.latest_run_id())
    st = (info or {}).get("stages", {}).get(args.stage)
    if args.stage not in pipe.stages:
        return fail(f"unknown stage '{args.stage}'; fix: use one of: {', '.join(pipe.stages)}")
    rec = store.record(st["key"]) if st and st.get("key") else None
    if rec is None:
        return fail(f"stage '{args.stage}' has no recorded log in the latest run")
    sys.stdout.write(store.object_path(rec["provenance"]["log"]).read_text(errors="replace"))
    return 0

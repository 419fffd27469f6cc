"""`holoflow pin RUN [--remove]`: keep a run (an id, or ``latest``) through gc."""

from __future__ import annotations

from holoflow.commands.options import common, load, parser


def main(argv: list[str]) -> int:
    p = parser("pin")
    p.add_argument("run_id", metavar="RUN")
    p.add_argument("--remove", action="store_true", help="unpin")
    common(p, resolve_opts=False)
    args = p.parse_args(argv)
    _, store = load(args)
    rid = store.latest_run_id() if args.run_id == "latest" else args.run_id
    store.pin(rid or "latest", on=not args.remove)
    print(f"holoflow: {'unpinned' if args.remove else 'pinned'} run {rid}")
    return 0

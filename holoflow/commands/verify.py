"""`holoflow verify`: rehash every object of the store; quarantine and report damage (exit 1)."""

from __future__ import annotations

import sys

from holoflow.commands import fail
from holoflow.commands.options import common, load, parser


def main(argv: list[str]) -> int:
    p = parser("verify")
    common(p, resolve_opts=False)
    args = p.parse_args(argv)
    _, store = load(args)
    if not (store.root / "objects").is_dir():
        return fail(f"{store.root} is not a holoflow store (no objects/); fix: pass --store DIR")
    store.lock(None, "verify", lambda m: print(f"holoflow: {m}", file=sys.stderr))
    try:
        res = store.verify()
    finally:
        store.unlock()
    n = sum(1 for _ in store.iter_objects())
    for d in res["corrupt"]:
        print(f"corrupt object {d} (quarantined; the step that made it will rerun)")
    for stage, rel in res["missing"]:
        print(f"missing object for {stage}: {rel} (that step will rerun)")
    for name in res["damaged_records"]:
        print(f"damaged key record {name} (quarantined; its step will rerun)")
    ok = not res["corrupt"] and not res["missing"] and not res["damaged_records"]
    print(f"holoflow verify: {n} objects {'all match their hashes' if ok else 'checked; damage found'}")
    return 0 if ok else 1

"""`holoflow run [PROMPT]`: run the pipeline; cached steps are served from the store (docs/cli.md).
``--prompts FILE`` runs a batch of scenes over one store (docs/scale.md)."""

from __future__ import annotations

import json
import sys

from holoflow.commands.options import load, options, parser, run_flags


def main(argv: list[str]) -> int:
    p = parser("run")
    run_flags(p)
    args = p.parse_args(argv)
    from holoflow.flow.context import BatchItem, Context

    pipe, store = load(args)
    opts = options(args)
    if args.prompts:
        from holoflow.flow.batch import SceneSpec, make_scenes, read_prompts

        specs = read_prompts(args.prompts)
        if args.prompt is not None:
            specs = [SceneSpec(args.prompt)] + specs
        return run_items(args, make_scenes(pipe, store, opts, specs), batch=True)
    return run_items(args, [BatchItem(Context.build(pipe, store, opts), opts)], batch=False)


def run_items(args, items, batch: bool) -> int:
    """Run one scene, or a batch (``run --prompts``, ``sweep``); print its summary (or --json)."""
    from holoflow.flow.progress import make_display
    from holoflow.flow.scheduler import StepFailed, run_batch
    from holoflow.flow.summary import summary_lines
    from holoflow.networks.manifest import prepare

    prepare(items, args.models)
    display = make_display(sys.stderr if args.json else sys.stdout, fancy=None if not args.json else False)
    err = None
    try:
        with display:
            result = run_batch(items, display, lock_message=lambda m: print(f"holoflow: {m}", file=sys.stderr))
    except StepFailed as e:
        err = e
        result = {**e.batch, "error": str(e).splitlines()[0]}
    if not batch:
        result = result["scenes"][0] if err is None else {"ok": False, "error": result["error"]}
    if args.json:
        print(json.dumps(result, indent=1))
    elif err is None or batch:
        for line in summary_lines(result, items[0].ctx.store):
            print(line)
    if err is not None:
        print(f"holoflow: {err}", file=sys.stderr)
        return 1
    return 0

"""`holoflow sweep --grid STAGE.PARAM=V1,V2 ...`: a grid over params (x prompts) run as one batch
(docs/scale.md)."""

from __future__ import annotations

from holoflow.commands import fail
from holoflow.commands.options import load, options, parser, run_flags
from holoflow.commands.run import run_items


def main(argv: list[str]) -> int:
    p = parser("sweep")
    run_flags(p)
    p.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="STAGE.PARAM=V1,V2",
        help="a sweep axis (repeatable: the grid is their product)",
    )
    args = p.parse_args(argv)
    from holoflow.flow.batch import SceneSpec, make_scenes, read_prompts, sweep

    pipe, store = load(args)
    if not args.grid:
        return fail(
            "holoflow sweep needs at least one --grid STAGE.PARAM=V1,V2; fix: e.g. --grid detail.strength=0.3,0.5,0.7"
        )
    prompts = read_prompts(args.prompts) if args.prompts else []
    if args.prompt is not None or not prompts:
        prompts = [SceneSpec(args.prompt)] + prompts
    return run_items(args, make_scenes(pipe, store, options(args), sweep(prompts, args.grid)), batch=True)

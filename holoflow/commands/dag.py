"""`holoflow dag [--mermaid]`: the pipeline's DAG as text, or as a mermaid flowchart."""

from __future__ import annotations

from holoflow.commands.options import common, parser


def main(argv: list[str]) -> int:
    p = parser("dag")
    common(p, resolve_opts=False)
    p.add_argument("--mermaid", action="store_true")
    args = p.parse_args(argv)
    from holoflow.flow import pipeline

    pipe = pipeline.load(pipeline.find_pipeline(args.pipeline))
    if args.mermaid:
        print("flowchart TD")
        for s in pipe.stages.values():
            if not s.inputs and not any(s.name in t.inputs.values() for t in pipe.stages.values()):
                print(f"  {s.name}")
            for inp, up in s.inputs.items():
                print(f"  {up} -->|{inp}| {s.name}")
        return 0
    ins = {s.name: ", ".join(f"{inp}={up}" for inp, up in s.inputs.items()) or "-" for s in pipe.stages.values()}
    wn, wi = max(map(len, ins)), max(map(len, ins.values()))
    for s in pipe.stages.values():
        print(f"{s.name:<{wn}} <- {ins[s.name]:<{wi}}  [{s.engine}] {s.run}")
    return 0

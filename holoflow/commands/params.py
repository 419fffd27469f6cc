"""``holoflow params [STAGE]``: each stage's parameters from its typed class (holoflow/flow/params.py), as
text or as the Markdown tables of docs/stages.md, which are generated here and kept in sync by a test.

In docs/stages.md, each stage's table sits between ``<!-- params:STAGE -->`` and ``<!-- /params -->``;
``holoflow params --update-docs docs/stages.md`` rewrites them. Imports no heavy library.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from holoflow.flow import pipeline as pl

_BLOCK = re.compile(r"(<!-- params:(\w+) -->\n).*?(<!-- /params -->)", re.S)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(
        prog="holoflow params",
        description="Each stage's parameters: name, type, "
        "default, units, valid range, meaning (from the stage's `config:` class).",
    )
    ap.add_argument("stage", nargs="?", help="one stage (default: all)")
    ap.add_argument("--pipeline", default="pipeline.yaml", help="pipeline file (default ./pipeline.yaml)")
    ap.add_argument("--markdown", action="store_true", help="Markdown tables with a column per profile")
    ap.add_argument(
        "--update-docs", metavar="FILE", help="rewrite the generated tables in FILE (docs/stages.md) in place"
    )
    args = ap.parse_args(argv)
    pipe = pl.load(pl.find_pipeline(args.pipeline))
    if args.update_docs:
        path = Path(args.update_docs)
        path.write_text(update_doc(path.read_text(), pipe))
        return 0
    names = [args.stage] if args.stage else list(pipe.stages)
    for n in names:
        if n not in pipe.stages:
            raise pl.PipelineError(
                f"unknown stage '{n}'; fix: use one of: {', '.join(pipe.stages)}{pl._suggest(n, pipe.stages)}"
            )
    print("\n\n".join(markdown_table(pipe, n) if args.markdown else text_table(pipe, n) for n in names))
    return 0


def text_table(pipe: pl.Pipeline, stage: str) -> str:
    """``stage``'s params as aligned text: its class, engines, then one row per field."""
    s = pipe.stages[stage]
    if s.config is None:
        rows = [
            [k, type(v).__name__, _show(v), "", "", "(no config class: pipeline.yaml's value)"]
            for k, v in s.params.items()
        ]
        head = f"{stage}: params from pipeline.yaml (no `config:` class)"
    else:
        rows = [[f.name, f.type, _show(s.params[f.name]), f.units, f.range, f.doc] for f in s.config.fields_info()]
        head = (
            f"{stage}  ({s.config.__module__}:{s.config.__name__})  {_first_line(s.config.__doc__)}\n"
            f"engines: {', '.join(s.engines)} (default {s.engine})"
        )
    rows.insert(0, ["name", "type", "default", "units", "range", "meaning"])
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    return (
        head + "\n" + "\n".join("  " + "  ".join(c.ljust(w) for c, w in zip(r[:5], widths)) + "  " + r[5] for r in rows)
    )


def markdown_table(pipe: pl.Pipeline, stage: str) -> str:
    """``stage``'s params as the Markdown table of docs/stages.md: a column for the default profile's
    value, then one per other profile that sets the param (blank where it does not)."""
    s = pipe.stages[stage]
    if s.config is None:
        raise pl.PipelineError(f"stage '{stage}' has no `config:` class; fix: name its StageParams class")
    default = pipe.default_profile
    base = pl.resolve(pipe, default)[stage].params
    others = [p for p in pipe.profiles if p != default]
    head = (
        ["param", "type", f"default = `{default}`" if default else "default"]
        + [f"`{p}`" for p in others]
        + ["units", "valid", "meaning"]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for f in s.config.fields_info():
        cells = [f"`{f.name}`", f.type, f"`{_show(base[f.name])}`"]
        for p in others:
            over = pipe.profiles[p].get(stage, {})
            cells.append(f"`{_show(s.config.check(f.name, over[f.name]))}`" if f.name in over else "")
        cells += [f.units, f.range, f.doc]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def update_doc(text: str, pipe: pl.Pipeline) -> str:
    """``text`` with every ``<!-- params:STAGE -->`` block replaced by that stage's generated table."""
    return _BLOCK.sub(lambda m: f"{m.group(1)}{markdown_table(pipe, m.group(2))}\n{m.group(3)}", text)


def _show(v: Any) -> str:
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    if isinstance(v, bool):
        return "true" if v else "false"
    return '""' if v == "" else str(v)


def _first_line(doc: str | None) -> str:
    return (doc or "").strip().splitlines()[0] if doc else ""


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

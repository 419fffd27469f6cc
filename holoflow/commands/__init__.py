"""The `holoflow` command (docs/cli.md): one module per command in this package, each with
``main(argv) -> int``; this table names them and `main` imports only the one asked for, so start-up
costs the standard library and `holoflow status` or a fully cached `holoflow run` stay well under half
a second. ``holoflow bench NAME`` runs ``holoflow.bench.NAME``'s main the same way.

Exit codes: 0 ok, 1 a step failed (or verify found damage), 2 a user mistake (one line on stderr),
130 interrupted.
"""

from __future__ import annotations

import sys

# command -> (module with main(argv), one line of help)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("holoflow.commands.run", "run the pipeline (cached steps are served from the store)"),
    "sweep": ("holoflow.commands.sweep", "run a grid over params (x prompts) as one batch (docs/scale.md)"),
    "status": ("holoflow.commands.status", "fresh / stale / missing per stage, and why"),
    "dag": ("holoflow.commands.dag", "print the DAG (text, or mermaid)"),
    "inspect": ("holoflow.commands.inspect", "summarise an EXR/PLY file, or a stage's outputs in the latest run"),
    "gc": ("holoflow.commands.gc", "delete what the latest and pinned runs do not need (dry run unless --yes)"),
    "pin": ("holoflow.commands.pin", "keep a run through gc (RUN or 'latest')"),
    "verify": ("holoflow.commands.verify", "rehash every object; quarantine and report damage"),
    "log": ("holoflow.commands.log", "print a stage's log from the latest run"),
    "params": ("holoflow.commands.params", "each stage's params (type, default, range); --markdown"),
    "models": ("holoflow.commands.models", "list|random ...: the real engines' weights"),
    "view": ("holoflow.commands.view", "[RUN | STAGE | FILE.ply]: look around the scene in the browser (viser)"),
    "eval": ("holoflow.commands.evaluate", "score a run (against a truth set or its source) or procedural scenes"),
    "report": ("holoflow.report", "a run's report"),
    "bench": ("holoflow.bench", "NAME [ARGS]: run holoflow.bench.NAME (e.g. cache)"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage(), file=sys.stdout if argv else sys.stderr)
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        import difflib

        close = difflib.get_close_matches(name, COMMANDS, n=1)
        return fail(
            f"unknown command '{name}'"
            + (f" (did you mean '{close[0]}'?)" if close else "")
            + f"; fix: use one of: {', '.join(COMMANDS)}"
        )
    module = COMMANDS[name][0]
    if name == "bench":
        if not rest or rest[0].startswith("-"):
            return fail("usage: holoflow bench NAME [ARGS...]  (e.g. holoflow bench cache)")
        name, module, rest = f"bench {rest[0]}", f"holoflow.bench.{rest[0]}", rest[1:]
    from holoflow.flow.pipeline import PipelineError
    from holoflow.flow.store import StoreError

    try:
        return dispatch(module, name, rest)
    except (PipelineError, StoreError) as e:
        return fail(str(e))
    except OSError as e:  # the store's disk is full or read-only: one line, not a traceback
        from holoflow.flow.executors.failure import store_problem

        if (why := store_problem(e)) is None:
            raise
        return fail(why, 1)
    except KeyboardInterrupt:
        print("holoflow: interrupted; completed steps are kept", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


def usage() -> str:
    width = max(map(len, COMMANDS))
    return "\n".join(
        [
            "usage: holoflow COMMAND [ARGS...]  (holoflow COMMAND -h for its flags)",
            "",
            "Text prompt -> 3D Gaussian Splatting scene, as a DAG of stage-cached steps (docs/cli.md).",
            "",
            "commands:",
        ]
        + [f"  {n:<{width}}  {h}" for n, (_, h) in COMMANDS.items()]
    )


def fail(msg: str, code: int = 2) -> int:
    print(f"holoflow: error: {msg}", file=sys.stderr)
    return code


def dispatch(module: str, name: str, argv: list[str]) -> int:
    """``module.main(argv)``; a missing optional module is one line, not a traceback."""
    import importlib

    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name and module.startswith(e.name):
            return fail(f"`holoflow {name}` is not available: module {module} is not installed in this checkout")
        raise
    if not hasattr(mod, "main"):  # a part of another command (holoflow.bench.profiles: bench accuracy --profiles)
        what = (mod.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        return fail(f"`holoflow {name}` is not a command of its own" + (f"; {module} is {what}" if what else ""))
    return mod.main(argv) or 0


if __name__ == "__main__":
    sys.exit(main())

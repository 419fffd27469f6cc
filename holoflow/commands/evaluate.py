"""``holoflow eval``: scoring reconstructions, in two modes with their own flags (``--help`` of each lists them):

holoflow eval run RUN [--truth DIR] ...   one finished run (an id or 'latest', a photo's included) where a
                                          viewer looks, against a truth set when given
                                          (holoflow.commands.evaluate_run); also: holoflow eval --run RUN
holoflow eval scenes [PROMPT ...] ...     procedural scenes, the full method and the paper's ablations: the
                                          paper's tables (holoflow.commands.evaluate_scenes); also:
                                          holoflow eval [PROMPT ...]
"""

from __future__ import annotations


def main(argv: list[str] | None = None) -> int:
    import sys

    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] in (["-h"], ["--help"]):
        print(__doc__.strip())
        return 0
    if argv[:1] == ["run"]:
        from holoflow.commands import evaluate_run

        return evaluate_run.main(argv[1:])
    if any(a == "--run" or a.startswith("--run=") for a in argv):
        from holoflow.commands import evaluate_run

        return evaluate_run.main(argv, prog="holoflow eval --run")
    from holoflow.commands import evaluate_scenes

    return evaluate_scenes.main(argv[1:] if argv[:1] == ["scenes"] else argv)

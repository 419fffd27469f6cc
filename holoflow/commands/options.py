"""What the commands share: the common flags, loading the pipeline and store they name, and the run
options. Standard library at import."""

from __future__ import annotations

import argparse
import os

from holoflow.flow import pipeline
from holoflow.flow.context import Options
from holoflow.flow.store import Store


def parser(command: str) -> argparse.ArgumentParser:
    """The parser of ``holoflow COMMAND``, its description the command's line in the COMMANDS table."""
    from holoflow.commands import COMMANDS

    return argparse.ArgumentParser(prog=f"holoflow {command}", description=COMMANDS[command][1])


def common(sp, resolve_opts: bool = True) -> None:
    """--pipeline and --store; with ``resolve_opts`` also --profile, --set, --use, --seed."""
    sp.add_argument("--pipeline", default="pipeline.yaml", help="pipeline file (default ./pipeline.yaml)")
    sp.add_argument("--store", help="store folder (default $HOLOFLOW_STORE, else artifacts/ beside the pipeline file)")
    if resolve_opts:
        sp.add_argument(
            "--profile",
            help="profile from pipeline.yaml (default: its default_profile); a "
            "comma list applies in order: paper,tiny = the paper's engines at tiny sizes",
        )
        sp.add_argument(
            "--set",
            dest="sets",
            action="append",
            default=[],
            metavar="STAGE.PARAM=VALUE",
            help="override a param (YAML value, type-checked); STAGE.engine=NAME picks an engine",
        )
        sp.add_argument(
            "--use",
            dest="uses",
            action="append",
            default=[],
            metavar="STAGE=PATH",
            help="take a file or folder as STAGE's outputs; downstream runs from it",
        )
        sp.add_argument("--seed", type=int, help="override the pipeline's seed")


def run_flags(r) -> None:
    """The flags `run` and `sweep` share (beside ``common``)."""
    r.add_argument("prompt", nargs="?", help="text prompt (default: the last run's prompt)")
    common(r)
    r.add_argument("--from", dest="from_stage", metavar="STAGE", help="run STAGE and what depends on it")
    r.add_argument("--until", metavar="STAGE", help="run STAGE and what it depends on")
    r.add_argument("--only", metavar="STAGE", help="run STAGE alone (its inputs must be cached)")
    r.add_argument(
        "--force",
        action="append",
        default=[],
        metavar="STAGE",
        help="rerun STAGE even if cached ('all' for every stage); repeatable",
    )
    r.add_argument("--dry-run", action="store_true", help="say what would run; run nothing")
    r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    r.add_argument(
        "--device",
        choices=["cpu", "cuda", "auto"],
        help="device named in each job spec (default $HOLOFLOW_DEVICE, else cpu; auto = cuda when "
        "an NVIDIA driver is present); not part of the cache key",
    )
    r.add_argument(
        "--models",
        metavar="DIR",
        help="every real-model engine loads from DIR's manifest.json "
        "(`holoflow models random DIR` writes one; a folder of your own weights works too)",
    )
    r.add_argument("--lock-timeout", type=float, metavar="S", help="give up if the store stays locked S seconds")
    r.add_argument("-v", "--verbose", action="store_true", help="echo the steps' output")
    r.add_argument(
        "-j",
        "--jobs",
        type=int,
        default=1,
        metavar="N",
        help="run up to N CPU slots of independent steps at once (stages' resources:)",
    )
    r.add_argument(
        "--executor",
        choices=["local", "ray"],
        default="local",
        help="where steps run: this machine, or a Ray cluster (the ray extra)",
    )
    r.add_argument(
        "--address",
        help="Ray cluster address (default: start a local Ray with -j CPUs); "
        "a token for it is read from $RAY_AUTH_TOKEN, $RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token",
    )
    r.add_argument(
        "--connect-timeout",
        type=float,
        metavar="S",
        help="give up if no Ray cluster answers at --address within S seconds (default 60)",
    )
    r.add_argument(
        "--cold",
        action="store_true",
        help="exec every step as a fresh Python (default: Python steps fork from a warm "
        "template that imported torch & co once; also $HOLOFLOW_COLD=1)",
    )
    r.add_argument("--retries", type=int, metavar="N", help="retry a failed step N times (default 0 local, 2 ray)")
    r.add_argument(
        "--prompts", metavar="FILE", help="a batch: one prompt per line, or a YAML list of {prompt, set, seed}"
    )


def load(args):
    """(pipeline, store) that ``--pipeline`` / ``--store`` name."""
    path = pipeline.find_pipeline(args.pipeline)
    store = Store(args.store or os.environ.get("HOLOFLOW_STORE") or (path.parent / "artifacts"))
    return pipeline.load(path, cache_dir=store.root / "cache"), store


def options(args):
    """The run options (holoflow.flow.context.Options) the parsed flags give."""
    return Options(
        prompt=getattr(args, "prompt", None),
        profile=getattr(args, "profile", None),
        sets=getattr(args, "sets", []),
        uses=getattr(args, "uses", []),
        from_stage=getattr(args, "from_stage", None),
        until=getattr(args, "until", None),
        only=getattr(args, "only", None),
        force=getattr(args, "force", []),
        dry_run=getattr(args, "dry_run", False),
        seed=getattr(args, "seed", None),
        device=getattr(args, "device", None),
        lock_timeout=getattr(args, "lock_timeout", None),
        verbose=getattr(args, "verbose", False),
        jobs=getattr(args, "jobs", 1),
        executor=getattr(args, "executor", "local"),
        address=getattr(args, "address", None),
        connect_timeout=getattr(args, "connect_timeout", None),
        retries=getattr(args, "retries", None),
        cold=getattr(args, "cold", False) or os.environ.get("HOLOFLOW_COLD", "") not in ("", "0"),
    )

"""The `holoflow` command (docs/cli.md). Start-up imports only the standard library; subcommands import
what they need, so `holoflow status` and a fully cached `holoflow run` stay well under half a second.

Exit codes: 0 ok, 1 a step failed (or verify found damage), 2 a user mistake (one line on stderr),
130 interrupted.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

DISPATCH = {"eval": "holoflow.eval", "report": "holoflow.report", "models": "holoflow.models",
            "params": "holoflow.paramdocs", "view": "holoflow.view"}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    from .pipeline import PipelineError
    from .store import StoreError

    try:
        if argv and argv[0] in DISPATCH:
            return _dispatch(DISPATCH[argv[0]], argv[0], argv[1:])
        if argv and argv[0] == "bench":
            if len(argv) < 2 or argv[1].startswith("-"):
                return _fail("usage: holoflow bench NAME [ARGS...]  (e.g. holoflow bench cache)")
            return _dispatch(f"holoflow.bench.{argv[1]}", f"bench {argv[1]}", argv[2:])
        args = _parser().parse_args(argv)
        return args.func(args) or 0
    except (PipelineError, StoreError) as e:
        return _fail(str(e))
    except KeyboardInterrupt:
        print("holoflow: interrupted; completed steps are kept", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


def _fail(msg: str, code: int = 2) -> int:
    print(f"holoflow: error: {msg}", file=sys.stderr)
    return code


def _dispatch(module: str, name: str, argv: list[str]) -> int:
    import importlib

    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name and module.startswith(e.name):
            return _fail(f"`holoflow {name}` is not available: module {module} is not installed in this "
                         f"checkout")
        raise
    if not hasattr(mod, "main"):
        return _fail(f"`holoflow {name}`: {module} has no main(argv)")
    return mod.main(argv) or 0


# -- parser ----------------------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="holoflow", description="Text prompt -> 3D Gaussian Splatting scene, "
                                "as a DAG of stage-cached steps (docs/cli.md).")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def common(sp, resolve_opts=True):
        sp.add_argument("--pipeline", default="pipeline.yaml", help="pipeline file (default ./pipeline.yaml)")
        sp.add_argument("--store", help="store folder (default $HOLOFLOW_STORE, else artifacts/ beside "
                        "the pipeline file)")
        if resolve_opts:
            sp.add_argument("--profile", help="profile from pipeline.yaml (default: its default_profile); a "
                            "comma list applies in order: paper,tiny = the paper's engines at tiny sizes")
            sp.add_argument("--set", dest="sets", action="append", default=[], metavar="STAGE.PARAM=VALUE",
                            help="override a param (YAML value, type-checked); STAGE.engine=NAME picks an engine")
            sp.add_argument("--use", dest="uses", action="append", default=[], metavar="STAGE=PATH",
                            help="take a file or folder as STAGE's outputs; downstream runs from it")
            sp.add_argument("--seed", type=int, help="override the pipeline's seed")

    r = sub.add_parser("run", help="run the pipeline (cached steps are served from the store)")
    sw = sub.add_parser("sweep", help="run a grid over params (x prompts) as one batch (docs/scale.md)")
    for r in (sw, r):
        r.add_argument("prompt", nargs="?", help="text prompt (default: the last run's prompt)")
        common(r)
        r.add_argument("--from", dest="from_stage", metavar="STAGE", help="run STAGE and what depends on it")
        r.add_argument("--until", metavar="STAGE", help="run STAGE and what it depends on")
        r.add_argument("--only", metavar="STAGE", help="run STAGE alone (its inputs must be cached)")
        r.add_argument("--force", action="append", default=[], metavar="STAGE",
                       help="rerun STAGE even if cached ('all' for every stage); repeatable")
        r.add_argument("--dry-run", action="store_true", help="say what would run; run nothing")
        r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
        r.add_argument("--device", choices=["cpu", "cuda", "auto"],
                       help="device named in each job spec (default $HOLOFLOW_DEVICE, else cpu; auto = cuda when "
                       "an NVIDIA driver is present); not part of the cache key")
        r.add_argument("--models", metavar="DIR", help="every real-model engine loads from DIR's manifest.json "
                       "(`holoflow models random DIR` writes one; a folder of your own weights works too)")
        r.add_argument("--lock-timeout", type=float, metavar="S",
                       help="give up if the store stays locked S seconds")
        r.add_argument("-v", "--verbose", action="store_true", help="echo the steps' output")
        r.add_argument("-j", "--jobs", type=int, default=1, metavar="N",
                       help="run up to N CPU slots of independent steps at once (stages' resources:)")
        r.add_argument("--executor", choices=["local", "ray"], default="local",
                       help="where steps run: this machine, or a Ray cluster (the ray extra)")
        r.add_argument("--address", help="Ray cluster address (default: start a local Ray with -j CPUs)")
        r.add_argument("--cold", action="store_true",
                       help="exec every step as a fresh Python (default: Python steps fork from a warm "
                       "template that imported torch & co once; also $HOLOFLOW_COLD=1)")
        r.add_argument("--retries", type=int, metavar="N",
                       help="retry a failed step N times (default 0 local, 2 ray)")
        r.add_argument("--prompts", metavar="FILE",
                       help="a batch: one prompt per line, or a YAML list of {prompt, set, seed}")
    sw.add_argument("--grid", action="append", default=[], metavar="STAGE.PARAM=V1,V2",
                    help="a sweep axis (repeatable: the grid is their product)")
    sw.set_defaults(func=cmd_sweep)
    r.set_defaults(func=cmd_run)

    s = sub.add_parser("status", help="fresh / stale / missing per stage, and why")
    s.add_argument("prompt", nargs="?", help="text prompt (default: the last run's prompt)")
    common(s)
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_status)

    d = sub.add_parser("dag", help="print the DAG (text, or mermaid)")
    common(d, resolve_opts=False)
    d.add_argument("--mermaid", action="store_true")
    d.set_defaults(func=cmd_dag)

    i = sub.add_parser("inspect", help="summarise an EXR/PLY file, or a stage's outputs in the latest run")
    i.add_argument("target", metavar="PATH|STAGE")
    common(i, resolve_opts=False)
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=cmd_inspect)

    g = sub.add_parser("gc", help="delete what the latest and pinned runs do not need (dry run unless --yes)")
    common(g, resolve_opts=False)
    g.add_argument("--yes", action="store_true", help="really delete")
    g.set_defaults(func=cmd_gc)

    pn = sub.add_parser("pin", help="keep a run through gc (RUN or 'latest')")
    pn.add_argument("run_id", metavar="RUN")
    pn.add_argument("--remove", action="store_true", help="unpin")
    common(pn, resolve_opts=False)
    pn.set_defaults(func=cmd_pin)

    v = sub.add_parser("verify", help="rehash every object; quarantine and report damage")
    common(v, resolve_opts=False)
    v.set_defaults(func=cmd_verify)

    lg = sub.add_parser("log", help="print a stage's log from the latest run")
    lg.add_argument("stage")
    common(lg, resolve_opts=False)
    lg.set_defaults(func=cmd_log)

    sub.add_parser("bench", help="holoflow bench NAME [ARGS]: run holoflow.bench.NAME (e.g. cache)")
    sub.add_parser("eval", help="holoflow eval ...: accuracy against procedural ground truth")
    sub.add_parser("report", help="holoflow report ...: a run's report")
    sub.add_parser("view", help="holoflow view [RUN | STAGE | FILE.ply]: look around the scene in the browser (viser)")
    sub.add_parser("models", help="holoflow models list|random ...: the real engines' weights")
    sub.add_parser("params", help="holoflow params [STAGE] [--markdown]: each stage's params (type, default, range)")
    return p


def _load(args):
    from . import pipeline
    from .store import Store

    path = pipeline.find_pipeline(args.pipeline)
    store = Store(args.store or os.environ.get("HOLOFLOW_STORE") or (path.parent / "artifacts"))
    return pipeline.load(path, cache_dir=store.root / "cache"), store


def _options(args):
    from .runner import Options

    return Options(prompt=getattr(args, "prompt", None), profile=getattr(args, "profile", None),
                   sets=getattr(args, "sets", []), uses=getattr(args, "uses", []),
                   from_stage=getattr(args, "from_stage", None), until=getattr(args, "until", None),
                   only=getattr(args, "only", None), force=getattr(args, "force", []),
                   dry_run=getattr(args, "dry_run", False), seed=getattr(args, "seed", None),
                   device=getattr(args, "device", None), lock_timeout=getattr(args, "lock_timeout", None),
                   verbose=getattr(args, "verbose", False), jobs=getattr(args, "jobs", 1),
                   executor=getattr(args, "executor", "local"), address=getattr(args, "address", None),
                   retries=getattr(args, "retries", None), models=getattr(args, "models", None),
                   cold=getattr(args, "cold", False) or os.environ.get("HOLOFLOW_COLD", "") not in ("", "0"))


# -- commands --------------------------------------------------------------------------------------
def cmd_run(args) -> int:
    from .runner import Context, Scene

    pipe, store = _load(args)
    opts = _options(args)
    if args.prompts:
        from .batch import SceneSpec, make_scenes, read_prompts

        specs = read_prompts(args.prompts)
        if args.prompt is not None:
            specs = [SceneSpec(args.prompt)] + specs
        return _run_scenes(args, make_scenes(pipe, store, opts, specs), batch=True)
    return _run_scenes(args, [Scene(Context.build(pipe, store, opts), opts)], batch=False)


def cmd_sweep(args) -> int:
    from .batch import SceneSpec, make_scenes, read_prompts, sweep

    pipe, store = _load(args)
    if not args.grid:
        return _fail("holoflow sweep needs at least one --grid STAGE.PARAM=V1,V2; fix: e.g. "
                     "--grid detail.strength=0.3,0.5,0.7")
    prompts = read_prompts(args.prompts) if args.prompts else []
    if args.prompt is not None or not prompts:
        prompts = [SceneSpec(args.prompt)] + prompts
    return _run_scenes(args, make_scenes(pipe, store, _options(args), sweep(prompts, args.grid)), batch=True)


def _run_scenes(args, scenes, batch: bool) -> int:
    """Run one scene, or a batch (``run --prompts``, ``sweep``); print its summary (or --json)."""
    from .progress import make_display
    from .runner import StepFailed, run_batch
    from .summary import summary_lines

    display = make_display(sys.stderr if args.json else sys.stdout, fancy=None if not args.json else False)
    err = None
    try:
        with display:
            result = run_batch(scenes, display, lock_message=lambda m: print(f"holoflow: {m}", file=sys.stderr))
    except StepFailed as e:
        err = e
        result = {**e.batch, "error": str(e).splitlines()[0]}
    if not batch:
        result = result["scenes"][0] if err is None else {"ok": False, "error": result["error"]}
    if args.json:
        print(json.dumps(result, indent=1))
    elif err is None or batch:
        for line in summary_lines(result, scenes[0].ctx.store):
            print(line)
    if err is not None:
        print(f"holoflow: {err}", file=sys.stderr)
        return 1
    return 0


def cmd_status(args) -> int:
    from .runner import Context
    from .status import describe_ran, engine_note, status

    pipe, store = _load(args)
    ctx = Context.build(pipe, store, _options(args))
    st = status(ctx)
    if args.json:
        print(json.dumps({"prompt": ctx.prompt, "profile": ctx.profile, "stages": st}, indent=1))
        return 0
    width = max(len(n) for n in st)
    for name, s in st.items():
        why = "; ".join(s["reasons"]) or describe_ran(s.get("ran"))
        if s.get("engine"):
            why = f"{engine_note({'engine': s['engine']['ran'], 'why': s['engine']['why']})}; {why}"
        print(f"{name:<{width}}  {s['state']:<7}  {why}".rstrip())
    return 0


def cmd_dag(args) -> int:
    from . import pipeline

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


def cmd_inspect(args) -> int:
    from .inspect import InspectError, format_report, inspect_files, inspect_target

    target = Path(args.target)
    step = None
    try:
        if target.exists():
            report = inspect_target(target)
        else:
            pipe, store = _load(args)
            if args.target not in pipe.stages:
                return _fail(f"{args.target}: neither a file nor a stage; fix: give an EXR/PLY path or one "
                             f"of: {', '.join(pipe.stages)}")
            step, outputs = _stage_outputs(store, args.target)
            if outputs is None:
                return _fail(f"stage '{args.target}' has no recorded outputs; fix: holoflow run first")
            report = inspect_files({rel: store.object_path(e["digest"]) for rel, e in outputs.items()})
            report["step"] = step
    except InspectError as e:
        return _fail(str(e))
    if args.json:
        print(json.dumps(report, indent=1, default=str))
        return 0
    if step is not None:
        print("step: " + ", ".join(f"{k}={json.dumps(v)}" for k, v in step.items() if v is not None))
    print(format_report(report))
    return 0


def _stage_outputs(store, stage: str):
    """(step facts, output map) of ``stage`` in the latest run, else from its last record."""
    st = ((store.run_info(store.latest_run_id()) or {}).get("stages") or {}).get(stage)
    key = st.get("key") if st else store.last_key(stage)
    rec = store.record(key) if key else None
    if rec is None:
        return ({"how": st["how"], "source": st.get("source")}, st["outputs"]) if st else (None, None)
    prov = rec["provenance"]
    facts = {"key": rec["key"], **{k: prov.get(k) for k in ("engine", "params", "seed", "device", "wall_s",
                                                            "peak_rss_mb", "started", "meta", "versions")}}
    return facts, rec["outputs"]


def cmd_gc(args) -> int:
    _, store = _load(args)
    if not (store.root / "objects").is_dir():
        print(f"holoflow gc: {store.root} holds no store yet; nothing to do")
        return 0
    if args.yes:
        store.lock(None, "gc", lambda m: print(f"holoflow: {m}", file=sys.stderr))
    try:
        plan = store.gc_plan()
        mb = plan["bytes"] / 2**20
        verb = "deleted" if args.yes else "would delete"
        print(f"holoflow gc: {verb} {len(plan['runs'])} runs, {len(plan['keys'])} step records, "
              f"{len(plan['objects'])} objects ({mb:.1f} MiB); kept runs: {', '.join(plan['kept_runs']) or '-'}")
        if args.yes:
            store.gc_apply(plan)
        elif plan["objects"] or plan["runs"]:
            print("holoflow gc: dry run; pass --yes to delete")
    finally:
        store.unlock()
    return 0


def cmd_pin(args) -> int:
    _, store = _load(args)
    rid = store.latest_run_id() if args.run_id == "latest" else args.run_id
    store.pin(rid or "latest", on=not args.remove)
    print(f"holoflow: {'unpinned' if args.remove else 'pinned'} run {rid}")
    return 0


def cmd_verify(args) -> int:
    _, store = _load(args)
    if not (store.root / "objects").is_dir():
        return _fail(f"{store.root} is not a holoflow store (no objects/); fix: pass --store DIR")
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
    ok = not res["corrupt"] and not res["missing"]
    print(f"holoflow verify: {n} objects {'all match their hashes' if ok else 'checked; damage found'}")
    return 0 if ok else 1


def cmd_log(args) -> int:
    pipe, store = _load(args)
    info = store.run_info(store.latest_run_id())
    st = (info or {}).get("stages", {}).get(args.stage)
    if args.stage not in pipe.stages:
        return _fail(f"unknown stage '{args.stage}'; fix: use one of: {', '.join(pipe.stages)}")
    rec = store.record(st["key"]) if st and st.get("key") else None
    if rec is None:
        return _fail(f"stage '{args.stage}' has no recorded log in the latest run")
    sys.stdout.write(store.object_path(rec["provenance"]["log"]).read_text(errors="replace"))
    return 0


if __name__ == "__main__":
    sys.exit(main())

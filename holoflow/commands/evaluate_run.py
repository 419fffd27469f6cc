"""``holoflow eval run RUN [--truth DIR]``: score one finished run (a run id or ``latest``; a procedural
scene or a user's own panorama given by ``--use base_pano=FILE``) where a viewer looks.

- At the viewing size (default 512 px at the paper's 47.43 deg; holoflow.evaluation.viewing_size): the
  final scene at the base cameras against the source's own views (the photo itself for a photo), the
  zenith / nadir cameras apart, NIQE / BRISQUE ratios render / source, and novel cameras 0.25 / 0.5 /
  1 m off the centre looking sideways and back at the depth's edges: their empty (alpha < 0.5) and
  cracked (alpha < 0.9) fractions and NIQE / BRISQUE against the source's views; beside the profile's goals.
- With ``--truth DIR`` (a truth set, docs/truth-sets.md): the scene at each truth view's camera, per
  ring PSNR / SSIM, depth AbsRel / delta < 1.25 / scale, empty and cracked fractions
  (holoflow.evaluation.truth_scores), and one truth | render picture per ring.

Writes every number as JSON (``viewing.json``, ``truth-<set>.json``) and the pictures into ``--out``
(default: the run's own folder in the store, ``runs/<id>/eval/``), and prints where.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def parser(prog: str = "holoflow eval run") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=prog,
        description=__doc__.split("\n\n")[0],
        epilog="Procedural prompts and the paper's tables: `holoflow eval scenes`.",
    )
    p.add_argument("run", nargs="?", default=None, help="run id or 'latest'")
    p.add_argument("--run", dest="run_flag", default=None, metavar="RUN", help="the same as the positional RUN")
    p.add_argument(
        "--truth",
        type=Path,
        default=None,
        metavar="DIR",
        help="truth set folder (cameras.json + views/, docs/truth-sets.md): also score per ring",
    )
    p.add_argument("--store", type=Path, default=None, help="store (default $HOLOFLOW_STORE, else artifacts/)")
    p.add_argument("--size", type=int, default=512, help="viewing size, px square (paper 512)")
    p.add_argument("--fov", type=float, default=47.43, help="horizontal field of view, deg (paper 47.43)")
    p.add_argument(
        "--nr-cameras", type=int, default=12, help="NIQE / BRISQUE at this many seeded non-polar base cameras (0 = all)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the novel cameras and the NIQE / BRISQUE subset")
    p.add_argument("--backend", default="cpu", choices=["cpu", "reference", "gsplat"])
    p.add_argument(
        "--rig",
        default="edges",
        choices=["edges", "rings"],
        help="novel eyes: edges = moved short of the run's depth, looking sideways or back at its edges; "
        "rings = the truth sets' fixed eyes (8 a ring, sideways and back), the same for every run",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="folder for the JSON and pictures (default: runs/<id>/eval/ in the store)",
    )
    p.add_argument("--json", type=Path, default=None, help="also write the viewing-size numbers to this file")
    return p


def main(argv: list[str] | None = None, prog: str = "holoflow eval run") -> int:
    from holoflow.evaluation.runs import depth_engines, open_store
    from holoflow.evaluation.viewing_size import ViewingSpec, score_run, table

    args = parser(prog).parse_args(argv)
    want = args.run_flag or args.run
    if want is None:
        print(f"{prog}: which run? give RUN (an id or 'latest')", file=sys.stderr)
        return 2
    if args.truth is not None and not (args.truth / "cameras.json").is_file():
        print(f"{prog}: {args.truth} is not a truth set (no cameras.json; docs/truth-sets.md)", file=sys.stderr)
        return 2
    st = open_store(args.store)
    run_id = st.latest_run_id() if want == "latest" else want
    run_dir = st.run_dir(run_id) if run_id else None
    if run_dir is None or not (run_dir / "transfer_opt" / "scene.ply").is_file():
        print(
            f"holoflow eval: no finished run {want!r} (with transfer_opt/scene.ply) in {st.root}; "
            f"runs there: {', '.join(st.run_ids()[-5:]) or 'none'}",
            file=sys.stderr,
        )
        return 2
    out = args.out or run_dir / "eval"
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    info = st.run_info(run_id) or {}
    spec = ViewingSpec(
        size=args.size,
        fov_deg=args.fov,
        nr_cameras=args.nr_cameras,
        seed=args.seed,
        backend=args.backend,
        rig=args.rig,
    )
    r, _ = score_run(run_dir, info, spec)
    r.update(
        run=run_id,
        prompt=info.get("prompt"),
        profile=info.get("profile"),
        engines=depth_engines(run_dir),
        seconds_total=time.monotonic() - t0,
    )
    print(
        f"run {run_id} ({info.get('profile')}), depth made by: "
        + ", ".join(f"{k}={v}" for k, v in r["engines"].items())
    )
    print("\n".join(table(r, info.get("profile"))))
    print(f"scored in {r['seconds_total']:.1f} s")
    written = [out / "viewing.json"]
    for f in [out / "viewing.json"] + ([args.json] if args.json else []):
        f.write_text(json.dumps(r, indent=1, sort_keys=True))
    if args.truth is not None:
        written += truth_part(run_dir, run_id, args.truth, out, args.backend, r["engines"])
    print(f"holoflow eval: wrote {', '.join(str(w) for w in written)}", file=sys.stderr)
    return 0


def truth_part(run_dir: Path, run_id: str, truth: Path, out: Path, backend: str, engines: dict) -> list[Path]:
    """Score the run's scene against the truth set, print the ring table, write truth-<set>.json and the
    per-ring pictures into ``out``: the files written."""
    from holoflow.evaluation.truth_scores import ring_table, score_truth, write_pictures

    scores, pictures = score_truth(run_dir / "transfer_opt" / "scene.ply", truth, backend)
    name = truth.resolve().name
    files = write_pictures(pictures, out, f"truth-{name}")
    scores.update(run=run_id, engines=engines, pictures={k: p.name for k, p in files.items()})
    print("\n".join(ring_table(scores)))
    print(f"scored against the truth set in {scores['seconds']:.1f} s")
    f = out / f"truth-{name}.json"
    f.write_text(json.dumps(scores, indent=1, sort_keys=True))
    return [f, *files.values()]

"""The stage side of the step protocol (docs/stage-protocol.md).

A stage program is started as ``PROGRAM JOB.json``. It reads its job spec, reads the files of its
inputs (each input is a directory holding one upstream stage's outputs), writes its outputs under
``job.output_dir`` and exits 0. Anything it prints is kept as the step's log; lines starting with
``@progress `` or ``@meta `` carry JSON for the runner. A non-zero exit discards every output.

This module imports nothing heavy, so a stage pays only for what it uses.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, NoReturn, TypeVar

#: environment variables that size the thread pools of the numeric libraries a step may load
THREAD_VARS = (
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "NUMBA_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)

#: a progress callback, (done, total, what), as :meth:`Job.progress` takes it: engines and library loops
#: take one (or None), so a stage program passes ``job.progress`` straight through
Progress = Callable[[int, int, str], None] | None

P = TypeVar("P")
_loaded: list["Job"] = []  # the job this process loaded: run_main checks its outputs


@dataclass
class Job:
    """One step's job spec, as written by the runner."""

    stage: str
    engine: str
    params: dict[str, Any]
    seed: int
    prompt: str
    inputs: dict[str, Path]
    output_dir: Path
    work_dir: Path
    device: str = "cpu"
    cpus: int = 1  # the stage's resources.cpus, capped at this host's cores: its thread count
    extra: dict[str, Any] = field(default_factory=dict)
    _last_progress: float = field(default=0.0, repr=False)

    @classmethod
    def load(cls, path: str | Path) -> "Job":
        spec = json.loads(Path(path).read_text())
        job = cls(
            stage=spec["stage"],
            engine=spec["engine"],
            params=dict(spec.get("params", {})),
            seed=int(spec.get("seed", 0)),
            prompt=spec.get("prompt", ""),
            inputs={k: Path(v) for k, v in spec.get("inputs", {}).items()},
            output_dir=Path(spec["output_dir"]),
            work_dir=Path(spec.get("work_dir", spec["output_dir"])),
            device=spec.get("device", "cpu"),
            cpus=max(1, min(int(spec.get("cpus", 1)), os.cpu_count() or 1)),
            extra={k: v for k, v in spec.items() if k not in _KNOWN},
        )
        job.apply_threads()
        _loaded.append(job)
        return job

    def apply_threads(self) -> None:
        """Every thread pool of this process (OpenMP, MKL, OpenBLAS, numba, torch) uses ``cpus`` threads:
        set once here for every stage, before (or, for torch, also after) the libraries load."""
        for var in THREAD_VARS:
            os.environ[var] = str(self.cpus)
        if "torch" in sys.modules:
            sys.modules["torch"].set_num_threads(self.cpus)

    def torch_threads(self, n: int) -> None:
        """From here on torch uses ``n`` intra-op threads (the other pools keep ``cpus``): for a step whose
        torch work is on small tensors, where OpenMP barriers cost more than they save (docs/bench-startup.md)."""
        import torch

        torch.set_num_threads(n)

    def config(self, cls: type[P]) -> P:
        """The step's params as the stage's typed class (holoflow/flow/params.py), every value checked."""
        return cls.from_params(self.params)

    @classmethod
    def from_argv(cls, argv: list[str] | None = None) -> "Job":
        argv = sys.argv[1:] if argv is None else argv
        if len(argv) != 1:
            raise SystemExit("usage: STAGE_PROGRAM JOB.json  (started by `holoflow run`)")
        import atexit

        atexit.register(_gpu_peak_meta)
        return cls.load(argv[0])

    def input(self, name: str) -> Path:
        """Directory holding the files of input ``name`` (an upstream stage's outputs)."""
        try:
            return self.inputs[name]
        except KeyError:
            raise SystemExit(
                f"{self.stage}: input '{name}' missing from job spec (has: {sorted(self.inputs)}); check pipeline.yaml"
            ) from None

    def input_file(self, name: str, filename: str) -> Path:
        path = self.input(name) / filename
        if not path.exists():
            raise SystemExit(
                f"{self.stage}: input '{name}' has no file '{filename}' "
                f"(has: {sorted(p.name for p in self.input(name).iterdir())})"
            )
        return path

    def output(self, filename: str) -> Path:
        """Path for an output file (subfolders allowed); its parent is created."""
        path = (self.output_dir / filename).resolve()
        if self.output_dir.resolve() not in path.parents:
            raise ValueError(f"output name escapes the output folder: {filename!r}")
        path.parent.mkdir(parents=True, exist_ok=True)
        return path

    def progress(self, done: int, total: int, what: str = "", every_s: float = 0.2) -> None:
        """Report progress of a long loop; rate-limited so tight loops stay cheap."""
        now = time.monotonic()
        if done < total and now - self._last_progress < every_s:
            return
        self._last_progress = now
        emit("progress", {"done": int(done), "total": int(total), "what": what})

    def meta(self, **info: Any) -> None:
        """Add provenance (model identity, metrics, engine facts) to the step's record."""
        emit("meta", info)


class UserError(Exception):
    """A mistake the user can fix (bad param, missing weights): reported as one line, no traceback."""


USER_ERRORS = (UserError, ValueError, OSError, ImportError, json.JSONDecodeError)


def run_main(main: Callable[[], int], stage: str) -> NoReturn:
    """Exit with ``main()``'s code. A user mistake (``USER_ERRORS``) ends as one line on stderr,
    prefixed with the stage name, and exit code 1; anything else keeps its traceback (a bug).

    After exit 0 the job's output files are checked (holoflow.io.validate.output_problem): a NaN or inf
    (other than sky in a depth channel) fails the step here, in one line naming the stage and the file,
    so a non-finite value is caught at the step it first appears in and never committed."""
    try:
        code = main()
        if code == 0 and _loaded:
            from holoflow.io.validate import output_problem

            problem = output_problem(_loaded[-1].output_dir)
            if problem:
                sys.exit(f"{stage}: non-finite output, nothing committed: {problem} (docs/hard-inputs.md)")
    except USER_ERRORS as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        sys.exit(f"{stage}: {first}")
    sys.exit(code)


def _gpu_peak_meta() -> None:
    """At a step's exit: the peak GPU memory torch allocated (MiB) and the GPU's name, when the step
    used CUDA (torch imported and its CUDA context made); nothing otherwise."""
    torch = sys.modules.get("torch")
    if torch is not None and torch.cuda.is_initialized():
        emit(
            "meta",
            {"gpu_peak_mb": round(torch.cuda.max_memory_allocated() / 2**20, 1), "gpu": torch.cuda.get_device_name()},
        )


def emit(kind: str, payload: dict[str, Any]) -> None:
    sys.stdout.write(f"@{kind} {json.dumps(payload, sort_keys=True, default=str)}\n")
    sys.stdout.flush()


_KNOWN = {"stage", "engine", "params", "seed", "prompt", "inputs", "output_dir", "work_dir", "device", "cpus"}

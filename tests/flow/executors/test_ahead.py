"""Compile ahead (holoflow/flow/executors/ahead.py): the local executor starts one process for the steps to
come, which calls each module's compile_ahead in order (the module found under its search root), and
stops it when the run closes."""

import time
from pathlib import Path

from holoflow.flow.executors.local import LocalExecutor


def _kernels(tmp: Path, name: str, body: str) -> None:
    (tmp / f"{name}.py").write_text(f"def compile_ahead():\n{body}\n")


def test_expect_compiles_the_modules_ahead_in_order(tmp_path):
    log = tmp_path / "log"
    for name in ("first", "second"):
        _kernels(tmp_path, name, f"    open({str(log)!r}, 'a').write({name!r} + ' ')")
    ex = LocalExecutor(warm=False)
    ex.expect([], [f"{tmp_path}:first", f"{tmp_path}:second"])
    proc = ex.ahead
    ex.expect([], [f"{tmp_path}:second"])  # one process per run
    assert ex.ahead is proc
    assert proc.wait(timeout=60) == 0
    assert log.read_text() == "first second "
    ex.close()


def test_close_stops_a_process_still_compiling(tmp_path):
    _kernels(tmp_path, "slow", "    import time; time.sleep(60)")
    ex = LocalExecutor(warm=False)
    ex.expect([], [f"{tmp_path}:slow"])
    t0 = time.monotonic()
    ex.close()
    assert ex.ahead.returncode is not None and time.monotonic() - t0 < 10


def test_no_kernels_no_process():
    ex = LocalExecutor(warm=False)
    ex.expect([], [])
    assert ex.ahead is None
    ex.close()

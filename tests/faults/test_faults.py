"""Faults during a tiny run (docs/faults.md): a full disk, a store that turns read-only, a step out of
memory, SIGTERM / SIGHUP to `holoflow run`, a cut-short key record or object, `gc --yes` beside a run.

Each starts from a copy of one undisturbed reference run (module fixture) less its last step
(export, 0.3 s), so a test recomputes one step, not the pipeline. Each checks that the user sees one
clear `holoflow:` line and no traceback, that `holoflow verify` is clean afterwards, and that the
next `holoflow run` completes with the reference's bytes for all thirteen stages (the same machine
and code: every stage is deterministic for a fixed seed here, and export only re-encodes its inputs).
"""

import json
import os
import resource
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from .faultkit import (
    TAIL,
    final_bytes,
    holoflow,
    one_clear_line,
    popen,
    run_json,
    verify_clean,
    wait_for_step,
    without_tail,
)

pytestmark = pytest.mark.timeout(600)


def _complete_again(store: Path, reference) -> dict:
    """verify is clean, then a run completes with the reference's bytes; returns its summary."""
    verify_clean(store)
    summary = run_json(store)
    assert final_bytes(summary) == final_bytes(reference[1])
    verify_clean(store)
    assert list((store / "tmp").iterdir()) == []
    return summary


def _nothing_lost(store: Path, reference) -> None:
    """Every record of the store copied from the reference is still there with intact objects."""
    ref_keys = {p.name for p in (reference[0] / "keys").glob("*.json")}
    have = {p.name for p in (store / "keys").glob("*.json")}
    assert have <= ref_keys and len(ref_keys - have) <= 1  # at most the tail's record is missing


@pytest.fixture
def mount(tmp_path):
    """A fresh tmpfs mounted at a temp folder (root only); unmounted after the test."""
    point = tmp_path / "mnt"
    point.mkdir()

    def do(size: str) -> Path:
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(point)], capture_output=True, text=True
        )
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here (needs root): {done.stderr.strip()}")
        return point

    yield do
    if os.path.ismount(point):
        subprocess.run(["umount", "-l", str(point)], check=False)


def _fill(point: Path, leave: int) -> Path:
    """A filler file taking all the free space of ``point`` but ``leave`` bytes."""
    st = os.statvfs(point)
    filler = point / "filler"
    with open(filler, "wb") as f:
        f.write(b"\0" * max(0, st.f_bavail * st.f_frsize - leave))
    return filler


def _staged_bytes(reference) -> int:
    """What the tail step writes: its outputs and its log (from the reference's record)."""
    store, summary = reference
    rec = json.loads((store / "keys" / f"{summary['stages'][TAIL]['key']}.json").read_text())
    return sum(e["size"] for e in rec["outputs"].values()) + rec["provenance"]["log_size"]


# free space left when the tail step runs: none (the run cannot even record itself), half of what
# the step writes (its own writes fail), and what it writes plus 96 KiB (its outputs fit; the
# commit's record, run.json or links run out of room, depending on rounding to pages)
@pytest.mark.parametrize("leave", ["none", "half", "outputs"])
def test_disk_full(reference, mount, leave):
    point = mount("32m")
    store = without_tail(reference[0], point / "store")
    staged = _staged_bytes(reference)
    filler = _fill(point, {"none": 0, "half": staged // 2, "outputs": staged + 96 * 1024}[leave])
    done = holoflow(store, "run")
    assert done.returncode == 1
    one_clear_line(done.stderr, "disk is full", "kept", "fix:")
    _nothing_lost(store, reference)
    filler.unlink()
    _complete_again(store, reference)


def _remount(point: Path, mode: str) -> None:
    subprocess.run(["mount", "-o", f"remount,{mode}", str(point)], check=True)


@pytest.mark.parametrize("when", ["before", "mid-step"])
def test_store_turns_read_only(reference, mount, when):
    point = mount("32m")
    store = without_tail(reference[0], point / "store")
    if when == "before":
        _remount(point, "ro")
        done = holoflow(store, "run")
        assert done.returncode == 2
        one_clear_line(done.stderr, "not writable", "Read-only file system", "fix:")
        _remount(point, "rw")
    else:
        # a file system with files open for writing refuses `remount,ro`; a read-only bind mount of it
        # over itself turns every new open read-only at once, as a kernel's errors=remount-ro would
        proc = popen(store)
        step = wait_for_step(proc, TAIL)
        os.kill(step, signal.SIGSTOP)  # hold the step mid-way while the disk turns read-only
        subprocess.run(["mount", "--bind", str(point), str(point)], check=True)
        try:
            _remount(point, "bind,ro")
            os.kill(step, signal.SIGCONT)
            out, err = proc.communicate(timeout=120)
        finally:
            subprocess.run(["umount", str(point)], check=True)  # the bind mount: writable again
        assert proc.returncode == 1, err
        one_clear_line(err, "read-only")
    _nothing_lost(store, reference)
    _complete_again(store, reference)


def test_step_out_of_memory(reference, tmp_path):
    """The tail step gets an address-space rlimit just above what it has mapped (prlimit on its pid,
    as a memory-capped container would): its next allocation fails, the run says so in one line."""
    # The limit lands wherever the step happens to be when the test catches it: a step caught after its
    # last allocation (a busy machine slows the catch) finishes fine, so that try says nothing and the
    # next one starts from a fresh copy of the store. Native code may also crash on a failed allocation
    # instead of raising MemoryError (numpy's take_along_axis did, in export's packing: SIGSEGV, which
    # the runner reports as "killed by signal 11"); that try says nothing about the runner either.
    for attempt in range(6):
        store = without_tail(reference[0], tmp_path / f"store{attempt}")
        proc = popen(store)
        step = wait_for_step(proc, TAIL)
        os.kill(step, signal.SIGSTOP)
        vm = _vm_size(step)
        resource.prlimit(step, resource.RLIMIT_AS, (vm + (1 << 20), vm + (1 << 20)))
        os.kill(step, signal.SIGCONT)
        out, err = proc.communicate(timeout=120)
        if proc.returncode != 0 and "killed by signal" not in err:
            break
    assert proc.returncode == 1, err
    line = one_clear_line(err, f"stage '{TAIL}' failed", "out of memory")
    assert "nothing from it was committed" in line
    _nothing_lost(store, reference)
    _complete_again(store, reference)


def _vm_size(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmSize")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_run_signalled_mid_step(reference, tmp_path, sig):
    store = without_tail(reference[0], tmp_path / "store")
    proc = popen(store)
    step = wait_for_step(proc, TAIL)
    os.kill(step, signal.SIGSTOP)  # the step is surely mid-way when the signal comes
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    one_clear_line(err, "interrupted", "completed steps are kept")
    assert not Path(f"/proc/{step}").exists() or "Z" in Path(f"/proc/{step}/stat").read_text().split()[2]
    _nothing_lost(store, reference)
    _complete_again(store, reference)


def test_truncated_key_record(reference, tmp_path):
    store = tmp_path / "store"
    shutil.copytree(reference[0], store, symlinks=True)
    rec = store / "keys" / f"{reference[1]['stages'][TAIL]['key']}.json"
    rec.write_bytes(rec.read_bytes()[: rec.stat().st_size // 2])
    done = holoflow(store, "run", "--json")
    assert done.returncode == 0, done.stderr
    one_clear_line(done.stderr, "key record", "damaged", "recomputed")
    summary = json.loads(done.stdout)
    assert {n for n, s in summary["stages"].items() if s["how"] == "ran"} == {TAIL}
    assert final_bytes(summary) == final_bytes(reference[1])
    assert any((store / "corrupt").iterdir())
    summary = _complete_again(store, reference)
    assert {s["how"] for s in summary["stages"].values()} == {"cached"}


def test_truncated_object(reference, tmp_path):
    store = tmp_path / "store"
    shutil.copytree(reference[0], store, symlinks=True)
    outputs = reference[1]["stages"][TAIL]["outputs"]
    name, digest = max(outputs.items(), key=lambda kv: (store / "objects" / kv[1][:2] / kv[1]).stat().st_size)
    obj = store / "objects" / digest[:2] / digest
    with open(obj, "r+b") as f:  # root writes through the 0444 mode, as a bad disk would
        f.truncate(obj.stat().st_size // 2)
    done = holoflow(store, "verify")
    assert done.returncode == 1 and f"corrupt object {digest}" in done.stdout
    done = holoflow(store, "run")
    assert done.returncode == 0, done.stderr
    summary = _complete_again(store, reference)
    assert summary["stages"][TAIL]["outputs"][name] == digest


def test_gc_during_run(reference, tmp_path):
    store = without_tail(reference[0], tmp_path / "store")
    run_json(store, "--until", "detail")  # an older run (all cached) for gc to delete
    proc = popen(store)
    step = wait_for_step(proc, TAIL)
    os.kill(step, signal.SIGSTOP)
    gc = popen(store, "gc", "--yes")
    time.sleep(1.0)
    assert gc.poll() is None  # gc waits for the run's lock
    os.kill(step, signal.SIGCONT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    gout, gerr = gc.communicate(timeout=60)
    assert gc.returncode == 0, gerr
    assert "locked by" in gerr and "waiting" in gerr
    assert "deleted 1 runs" in gout
    summary = _complete_again(store, reference)
    assert {s["how"] for s in summary["stages"].values()} == {"cached"}

"""The content-addressed store (docs/store.md): immutable objects, key records, runs, lock, gc, verify.

Layout under the store root::

    objects/ab/abcdef...      read-only files named by the sha256 of their bytes
    keys/<key>.json           one record per computed step: outputs + provenance (written last)
    stages/<stage>.json       {"key": last recorded key of that stage} (for `status` reasons)
    runs/<run-id>/run.json    what a run used: stage -> key, outputs, how (ran/cached/cutoff/used)
    runs/<run-id>/<stage>/..  symlinks into objects/ (browsable, and the inputs of later steps)
    latest                    symlink -> runs/<run-id> of the last run
    pins/<run-id>             pinned runs survive gc
    tmp/                      staging; anything here is garbage once the lock is free
    corrupt/                  objects whose bytes no longer match their name are moved here
    cache/code.json           (path, size, mtime_ns) -> source digest, so code hashing is cheap
    cache/pipeline.json       the parsed pipeline.yaml, keyed by its (path, size, mtime_ns)
    cache/imports.json        (a --use image's sha256, the decoder's code) -> its imported EXR + facts
    lock                      fcntl.flock held by `run` and `gc --yes`

Crash safety: an object appears only through a hard link (else ``os.replace``) of a complete, fsynced
file; a key record is written (tmp + fsync + link) after all its objects exist. A SIGKILL at any moment
leaves at worst stray files in tmp/, which the next locked operation removes.

Concurrent commits (threads of `run -j N`, Ray workers on several hosts sharing the store): temporary
names are unique per writer, and both objects and key records are created with ``os.link``, which never
replaces an existing name: when several workers finish the same key at once the first commit wins and
the others adopt it (an object's bytes are identical by construction: its name is their hash).
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shutil
import stat
import sys
import time
from pathlib import Path
from typing import Any, Iterator

CHUNK = 1 << 20


class StoreError(Exception):
    """A store that cannot be used (unwritable, locked past the timeout, inconsistent): one line."""


def canonical_json(obj: Any) -> str:
    """Canonical JSON: sorted keys, no whitespace, NaN forbidden; the cache key is its sha256."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(CHUNK):
            h.update(chunk)
    return h.hexdigest()


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never a partial one."""
    os.replace(_write_tmp(path, text), path)


def _write_tmp(path: Path, text: str) -> Path:
    """A complete, fsynced sibling of ``path`` under a name unique to this writer (host, pid, random)."""
    tmp = path.with_name(f".{path.name}.{os.uname().nodename}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
    try:
        with open(tmp, "x") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:  # a full disk: leave no partial file behind
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    return tmp


def link_or_replace(src: Path, dest: Path) -> bool:
    """Give ``src``'s file the name ``dest`` unless ``dest`` exists (first wins); ``src`` is gone after.

    Returns True if this call created ``dest``. On a filesystem without hard links it falls back to
    ``os.replace`` (last wins; callers only use it where every contender writes the same bytes).
    """
    try:
        os.link(src, dest)
    except FileExistsError:
        os.unlink(src)
        return False
    except OSError as e:
        if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
            raise
        os.replace(src, dest)
        return True
    os.unlink(src)
    return True


def read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None


class Store:
    """A store rooted at ``root``; creating the object does not touch the disk."""

    def __init__(self, root: str | Path):
        self.root = Path(root).absolute()
        self._lock_fd: int | None = None

    # -- layout ---------------------------------------------------------------------------------
    def object_path(self, digest: str) -> Path:
        return self.root / "objects" / digest[:2] / digest

    def key_path(self, key: str) -> Path:
        return self.root / "keys" / f"{key}.json"

    def run_dir(self, run_id: str) -> Path:
        return self.root / "runs" / run_id

    def ensure(self) -> None:
        """Create the layout; a clear StoreError if the place is not writable."""
        try:
            for sub in ("objects", "keys", "stages", "runs", "pins", "tmp", "cache"):
                (self.root / sub).mkdir(parents=True, exist_ok=True)
            # beside tmp/, not in it: the lock holder empties tmp/ at any moment
            probe = self.root / f".probe-{os.getpid()}-{os.urandom(4).hex()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as e:
            raise StoreError(
                f"store {self.root} is not writable ({e.strerror}); fix: pass --store DIR "
                f"or set HOLOFLOW_STORE to a writable folder"
            ) from None

    # -- lock -----------------------------------------------------------------------------------
    def lock(self, timeout: float | None = None, what: str = "run", wait_message=None) -> None:
        """Take the store's exclusive lock; waits (saying so) up to ``timeout`` seconds (None = forever)."""
        path = self.root / "lock"
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_fd(fd)
            if wait_message:
                wait_message(
                    f"store {self.root} is locked by {holder or 'another holoflow'}; waiting"
                    + (f" up to {timeout:g} s" if timeout is not None else "")
                    + " ..."
                )
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if deadline is not None and time.monotonic() >= deadline:
                        os.close(fd)
                        raise StoreError(
                            f"store {self.root} still locked by {holder or 'another holoflow'}"
                            f" after {timeout:g} s; fix: wait for it, or raise --lock-timeout"
                        )
                    time.sleep(0.1)
        try:  # who holds it, for the next one that waits (not on a full disk)
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"pid {os.getpid()} ({what}, since {time.strftime('%H:%M:%S')})".encode(), 0)
        except OSError:
            pass
        self._lock_fd = fd
        self.clean_tmp()

    def unlock(self) -> None:
        if self._lock_fd is not None:
            try:
                os.ftruncate(self._lock_fd, 0)
            except OSError:
                pass
            fcntl.flock(self._lock_fd, fcntl.LOCK_UN)
            os.close(self._lock_fd)
            self._lock_fd = None

    def clean_tmp(self) -> None:
        """Remove staging left by killed runs (only call while holding the lock)."""
        tmp = self.root / "tmp"
        if tmp.is_dir():
            for p in tmp.iterdir():
                remove_tree(p)

    def staging(self, prefix: str) -> Path:
        import tempfile

        return Path(tempfile.mkdtemp(prefix=f"{prefix}-", dir=self.root / "tmp"))

    # -- objects --------------------------------------------------------------------------------
    def put(self, src: Path) -> dict[str, Any]:
        """Move file ``src`` (inside tmp/) into objects/; returns {digest, size, mtime_ns}."""
        with open(src, "rb") as f:
            h = hashlib.sha256()
            while chunk := f.read(CHUNK):
                h.update(chunk)
            os.fsync(f.fileno())
        digest = h.hexdigest()
        dest = self.object_path(digest)
        try:
            st = dest.stat()
            if st.st_size == src.stat().st_size:
                src.unlink()
                return {"digest": digest, "size": st.st_size, "mtime_ns": st.st_mtime_ns}
            self.quarantine(digest)
        except FileNotFoundError:
            pass
        dest.parent.mkdir(exist_ok=True)
        os.chmod(src, 0o444)
        link_or_replace(src, dest)  # another worker may have committed the same bytes meanwhile
        st = dest.stat()
        return {"digest": digest, "size": st.st_size, "mtime_ns": st.st_mtime_ns}

    def check(self, entry: dict[str, Any]) -> bool:
        """Is the object of ``entry`` ({digest, size, mtime_ns}) present and intact?

        A stat matching the record is trusted; otherwise the bytes are rehashed, a mismatch moves the
        object to corrupt/ and counts as missing. A good rehash updates ``entry['mtime_ns']`` in place.
        """
        path = self.object_path(entry["digest"])
        try:
            st = path.stat()
        except FileNotFoundError:
            return False
        if st.st_size == entry["size"] and st.st_mtime_ns == entry.get("mtime_ns"):
            return True
        if st.st_size == entry["size"] and sha256_file(path) == entry["digest"]:
            entry["mtime_ns"] = st.st_mtime_ns
            return True
        self.quarantine(entry["digest"])
        return False

    def quarantine(self, digest: str) -> Path | None:
        src = self.object_path(digest)
        dest = self.root / "corrupt" / f"{digest}.{time.time_ns()}"
        dest.parent.mkdir(exist_ok=True)
        try:
            os.replace(src, dest)
            print(
                f"holoflow: object {digest[:12]} no longer matches its hash; moved to {dest} and will be recomputed",
                file=sys.stderr,
            )
            return dest
        except FileNotFoundError:
            return None

    def iter_objects(self) -> Iterator[Path]:
        base = self.root / "objects"
        if base.is_dir():
            for sub in sorted(base.iterdir()):
                if sub.is_dir():
                    yield from sorted(sub.iterdir())

    # -- key records ----------------------------------------------------------------------------
    def record(self, key: str) -> dict | None:
        """The key record of ``key``; None when there is none, or when it is damaged (cut short, not
        JSON): that one is moved to corrupt/ with a line on stderr, and its step runs again."""
        path = self.key_path(key)
        rec = read_json(path)
        if rec is None and path.is_file():
            self.quarantine_record(path)
        return rec

    def quarantine_record(self, path: Path, say: bool = True) -> None:
        dest = self.root / "corrupt" / f"{path.name}.{time.time_ns()}"
        try:
            dest.parent.mkdir(exist_ok=True)
            os.replace(path, dest)
            where = f"moved to {dest}"
        except FileNotFoundError:
            return
        except OSError as e:
            where = f"left in place ({e.strerror})"
        if say:
            print(
                f"holoflow: key record {path.name} is damaged (not complete JSON); {where}; its step will "
                f"be recomputed",
                file=sys.stderr,
            )

    def write_record(self, rec: dict, replace: bool = True) -> dict:
        """Commit a key record; returns the record now in force.

        ``replace=False`` (a normal step): if an intact record for the key is already committed (another
        worker finished the same key first), that one is kept and returned. ``replace=True`` (--force)
        always installs ``rec``.
        """
        path = self.key_path(rec["key"])
        tmp = _write_tmp(path, json.dumps(rec, indent=1, sort_keys=True))
        if replace:
            os.replace(tmp, path)
        elif not link_or_replace(tmp, path):
            existing = self.record(rec["key"])
            if existing is not None and self.outputs_ok(existing):
                return existing
            write_atomic(path, json.dumps(rec, indent=1, sort_keys=True))  # the old one was damaged
        try:  # committed above; the pointer only serves `status` reasons
            write_atomic(self.root / "stages" / f"{rec['stage']}.json", json.dumps({"key": rec["key"]}))
        except OSError:
            pass
        return rec

    def last_key(self, stage: str) -> str | None:
        rec = read_json(self.root / "stages" / f"{stage}.json")
        return rec.get("key") if rec else None

    def outputs_ok(self, rec: dict) -> bool:
        """All outputs (and nothing else matters) of a record present and intact."""
        return all(self.check(e) for e in rec["outputs"].values())

    # -- runs -----------------------------------------------------------------------------------
    def new_run_id(self) -> str:
        base = time.strftime("%Y%m%d-%H%M%S")
        n = 0
        while True:
            rid = base if n == 0 else f"{base}-{n}"
            try:
                self.run_dir(rid).mkdir(parents=True)
                return rid
            except FileExistsError:
                n += 1

    def link_outputs(self, run_id: str, stage: str, outputs: dict[str, dict]) -> Path:
        """runs/<run-id>/<stage>/<file> -> objects (relative links, so the store can move)."""
        d = self.run_dir(run_id) / stage
        if d.exists():
            remove_tree(d)
        d.mkdir(parents=True)
        for rel, entry in outputs.items():
            link = d / rel
            link.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(os.path.relpath(self.object_path(entry["digest"]), link.parent), link)
        return d

    def write_run(self, run_id: str, info: dict, latest: bool = True) -> None:
        write_atomic(self.run_dir(run_id) / "run.json", json.dumps(info, indent=1, sort_keys=True))
        if latest:
            tmp = self.root / "tmp" / f".latest.{os.getpid()}"
            if tmp.is_symlink():
                tmp.unlink()
            os.symlink(os.path.join("runs", run_id), tmp)
            os.replace(tmp, self.root / "latest")

    def latest_run_id(self) -> str | None:
        try:
            return os.path.basename(os.readlink(self.root / "latest"))
        except OSError:
            return None

    def run_info(self, run_id: str | None) -> dict | None:
        return read_json(self.run_dir(run_id) / "run.json") if run_id else None

    def run_ids(self) -> list[str]:
        d = self.root / "runs"
        return sorted(p.name for p in d.iterdir() if p.is_dir()) if d.is_dir() else []

    def pinned(self) -> list[str]:
        d = self.root / "pins"
        return sorted(p.name for p in d.iterdir()) if d.is_dir() else []

    def pin(self, run_id: str, on: bool = True) -> None:
        if not (self.run_dir(run_id) / "run.json").is_file():
            raise StoreError(
                f"no run '{run_id}' in {self.root}; fix: pick one of: "
                f"{', '.join(self.run_ids()[-5:]) or '(no runs yet)'}"
            )
        p = self.root / "pins" / run_id
        if on:
            p.parent.mkdir(exist_ok=True)
            p.write_text("")
        elif p.exists():
            p.unlink()

    # -- gc / verify ----------------------------------------------------------------------------
    def gc_plan(self) -> dict[str, Any]:
        """What gc would delete: runs other than latest/pinned, key records and objects they don't reach.

        Kept: the latest run, pinned runs, each stage's last record (status explains against it), and
        every object those records name (outputs and logs).
        """
        keep_runs = set(self.pinned())
        if latest := self.latest_run_id():
            keep_runs.add(latest)
        keep_keys = set()
        for rid in keep_runs:
            info = self.run_info(rid) or {}
            keep_keys.update(s["key"] for s in info.get("stages", {}).values() if s.get("key"))
        sdir = self.root / "stages"
        for p in sdir.iterdir() if sdir.is_dir() else []:
            if k := (read_json(p) or {}).get("key"):
                keep_keys.add(k)
        keep_objects = set()
        all_keys = sorted((self.root / "keys").glob("*.json"))
        drop_keys = []
        for kp in all_keys:
            key = kp.name[:-5]
            if key in keep_keys:
                rec = read_json(kp) or {}
                keep_objects.update(e["digest"] for e in rec.get("outputs", {}).values())
                if log := rec.get("provenance", {}).get("log"):
                    keep_objects.add(log)
            else:
                drop_keys.append(kp)
        for rid in keep_runs:  # imported (--use) outputs are named only by their run
            info = self.run_info(rid) or {}
            for s in info.get("stages", {}).values():
                keep_objects.update(e["digest"] for e in s.get("outputs", {}).values())
        drop_objects = [p for p in self.iter_objects() if p.name not in keep_objects]
        drop_runs = [self.run_dir(r) for r in self.run_ids() if r not in keep_runs]
        return {
            "runs": drop_runs,
            "keys": drop_keys,
            "objects": drop_objects,
            "bytes": sum(p.stat().st_size for p in drop_objects),
            "kept_runs": sorted(keep_runs),
        }

    def gc_apply(self, plan: dict[str, Any]) -> None:
        for d in plan["runs"]:
            remove_tree(d)
        for p in plan["keys"]:
            p.unlink(missing_ok=True)
        for p in plan["objects"]:
            p.unlink(missing_ok=True)

    def verify(self) -> dict[str, list]:
        """Rehash every object; quarantine mismatches and damaged key records; list records whose
        objects are missing."""
        bad = []
        for p in self.iter_objects():
            if sha256_file(p) != p.name:
                self.quarantine(p.name)
                bad.append(p.name)
        missing, damaged = [], []
        for kp in sorted((self.root / "keys").glob("*.json")):
            rec = read_json(kp)
            if rec is None:
                self.quarantine_record(kp, say=False)
                damaged.append(kp.name)
                continue
            for rel, e in rec.get("outputs", {}).items():
                if not self.object_path(e["digest"]).is_file():
                    missing.append((rec.get("stage", "?"), rel))
        stray = list((self.root / "tmp").iterdir()) if (self.root / "tmp").is_dir() else []
        return {"corrupt": bad, "missing": missing, "damaged_records": damaged, "stray_tmp": [str(p) for p in stray]}


def _read_fd(fd: int) -> str:
    try:
        return os.pread(fd, 200, 0).decode(errors="replace").strip()
    except OSError:
        return ""


def remove_tree(p: Path) -> None:
    """Remove a file, link or tree, including read-only object copies."""
    if p.is_symlink() or p.is_file():
        p.unlink(missing_ok=True)
        return

    def onexc(func, path, exc):
        if isinstance(exc, OSError) and exc.errno in (errno.EACCES, errno.EPERM):
            os.chmod(os.path.dirname(path), stat.S_IRWXU)
            func(path)
        elif not isinstance(exc, FileNotFoundError):
            raise exc

    if sys.version_info >= (3, 12):
        shutil.rmtree(p, onexc=onexc)
    else:
        shutil.rmtree(p, onerror=lambda f, path, ei: onexc(f, path, ei[1]))

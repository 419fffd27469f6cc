"""A run that starts while another holds the store lock: the holder empties tmp/ at any moment, and
that must not make the newcomer's write probe fail and read as an unwritable store."""

from pathlib import Path

from holoflow.flow.store import Store


def test_write_probe_survives_the_lock_holder_emptying_tmp(tmp_path, monkeypatch):
    store = Store(tmp_path / "store")
    store.ensure()
    probes = []
    write_bytes = Path.write_bytes

    def write_then_holder_cleans(path, data):
        n = write_bytes(path, data)
        if path.name.startswith(".probe-"):  # the worst moment: between the probe's write and its unlink
            probes.append(path)
            (store.root / "tmp" / "staging-of-another-run").mkdir()
            store.clean_tmp()
        return n

    monkeypatch.setattr(Path, "write_bytes", write_then_holder_cleans)
    store.ensure()  # a StoreError here is the race this guards against
    assert len(probes) == 1  # the holder did clean while the probe existed
    assert list((store.root / "tmp").iterdir()) == []
    assert not probes[0].exists()  # and the probe leaves nothing behind

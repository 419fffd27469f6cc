"""A run that starts while another holds the store lock: the holder's cleaning of tmp/ may remove
the newcomer's write probe at any moment, and that must not read as an unwritable store (seen as
1 failed run of 4 in test_load.py; before the fix this loop failed 5 to 12 times in 3000, in 1 to 2 s)."""
import threading

from holoflow.flow.store import Store


def test_write_probe_survives_a_concurrent_clean_tmp(tmp_path):
    store = Store(tmp_path / "store")
    store.ensure()
    stop = threading.Event()

    def holder():                   # what the lock holder does when it takes the lock
        while not stop.is_set():
            store.clean_tmp()

    t = threading.Thread(target=holder)
    t.start()
    try:
        for _ in range(3000):
            store.ensure()
    finally:
        stop.set()
        t.join()

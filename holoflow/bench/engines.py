"""`holoflow bench engines`: time each real-model engine at preview and paper resolutions (docs/engines-bench.md).

The benchmark itself lives beside the engines in holoflow/engines/bench.py; this module is its `holoflow bench` name.
"""
from holoflow.engines.bench import main

__all__ = ["main"]

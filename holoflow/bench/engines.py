"""`holoflow bench engines`: time each real-model engine at preview and paper resolutions (docs/engines-bench.md).

The benchmark itself lives beside the engines in holoflow/networks/bench.py; this module is its `holoflow bench` name.
"""
from holoflow.networks.bench import main

__all__ = ["main"]

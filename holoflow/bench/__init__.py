"""Benchmarks: `holoflow bench NAME [ARGS]` runs ``holoflow.bench.NAME:main(argv)``; each writes a table to docs/.
``profiles`` and ``walking`` are parts of `holoflow bench accuracy` (``--profiles``, ``--walk``): their
``run(args)`` takes its parsed arguments.

Every table names the machine it was measured on and the load average around the measurement
(holoflow.evaluation.machine: ``machine()``, ``load()``): the development machines are shared 2-core CPUs.
"""

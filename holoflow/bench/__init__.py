"""Benchmarks: `holoflow bench NAME [ARGS]` runs ``holoflow.bench.NAME:main(argv)``; each writes a table to docs/."""

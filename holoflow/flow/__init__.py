"""The workflow core: pipeline.yaml and typed params, cache keys and the store, scheduling steps onto
executors, status and run records. Generic: it names no stage, engine or network, and imports no
domain package (tests/test_layers.py); stage programs meet it only through holoflow.stage."""

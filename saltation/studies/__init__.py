"""Batches of runs: concentration/flow sweeps on Dask, the Nino-Garcia validation, settling tests."""

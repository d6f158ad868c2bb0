"""Many scans: their order and names, link records, executors (local, Dask), the chain driver."""

"""Output: Parquet/ParaView/JSON writers, the progress bar, the run directory."""

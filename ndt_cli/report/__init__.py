"""What a run leaves behind: result files, CSV tables, plots and console summaries."""

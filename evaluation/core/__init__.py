"""What every benchmark shares: the config base, model specs and robot loading, seeds, the batched arm simulator,
sensing, run folders, tables, plots and the MLflow run."""

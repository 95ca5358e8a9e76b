"""Results: the results file and its sidecar, evaluation against ground truth, CSV tables
and plots."""

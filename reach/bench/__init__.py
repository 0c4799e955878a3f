"""The benchmark runner: suite files, executors, cross-checks, result tables and plots."""

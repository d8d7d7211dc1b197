"""Command-line tools that read a published dataset (validate, stats)."""

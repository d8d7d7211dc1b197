"""Command-line tools over a finished dataset: validate, stats, export."""

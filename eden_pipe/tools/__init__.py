"""Command-line tools that consume a finished dataset (exports to other formats)."""

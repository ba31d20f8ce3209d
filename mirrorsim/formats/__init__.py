"""Every reader and writer of a file: scene YAML, capture record, measurements, JSON/PNG."""

"""The files every wing shares: scene YAML, capture record, measurements, the dataset
table's columns, the strict readers, atomic JSON/PNG writers (a file only one pipeline
uses is read and written in that pipeline)."""

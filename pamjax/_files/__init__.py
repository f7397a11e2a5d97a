"""Files every workflow reads and writes: model files (a complete model as JSON, `model_file`), and a fit's
checkpoints with the fingerprint of the problem they belong to (`checkpoint`, `fingerprint`)."""

"""One-job helpers every layer may use, importing nothing else of labrig: errors and exit codes,
bounded YAML and JSON reading, the output-file rule, signal guards, run metadata, words, one
BLAS thread, the version."""
